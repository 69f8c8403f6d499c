#pragma once
// Private to the library: the pieces of the compliance file that the shard
// files (partial_file.cpp) share with it.

#include <hdf5.h>

#include <filesystem>

#include "palpate/file/compliance_file.hpp"
#include "palpate/file/cut_region_data.hpp"
#include "palpate/file/detail/dataset_io.hpp"
#include "palpate/file/hash.hpp"

namespace palpate::detail {

/// The root attributes of @p model, with `format` = @p format.
void write_root_attributes(hid_t file, const ComplianceModel& model, const char* format);

/// /mesh/*, /material/* and /compliance/vertex_ids, in digest order, into @p digest.
void write_model_datasets(hid_t file, const ComplianceModel& model, Sha256& digest);

/// /cut_region/* (1.3), in digest order, into @p digest (cut_region_data.cpp).
void write_cut_region(hid_t file, const CutRegionData& region, Sha256& digest);
/// /cut_region/* read, in the order written, through @p r (its digest); not checked.
CutRegionData read_cut_region(Reader& r);

/// read_compliance_file() for a file of @p format: kComplianceFormatName, or
/// kPartialFormatName (everything but G: its rows are checked, not read).
/// @p G32 may be null (G in double).
ComplianceModel read_compliance_file(const std::filesystem::path& path, Eigen::MatrixXd* G,
                                     Eigen::MatrixXf* G32, const char* format);

}  // namespace palpate::detail
