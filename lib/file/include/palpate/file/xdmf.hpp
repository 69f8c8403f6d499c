#pragma once
/// @file
/// The XDMF sidecar of a compliance file: a small XML file `X.xdmf` next to
/// `X.h5` that describes the file's meshes and per-vertex arrays to viewers
/// (ParaView's Xdmf3 reader, VisIt, meshio). It holds no numbers itself: every
/// array is a reference `X.h5:/dataset`, by file name relative to the
/// sidecar's directory, so the two files move together. Layout:
/// docs/compliance-file.md, "The XDMF sidecar".

#include <filesystem>
#include <string>

#include "palpate/file/compliance_file.hpp"

namespace palpate {

/// The sidecar of @p compliance_file: same directory and stem, extension
/// `.xdmf` (`organ.h5` → `organ.xdmf`).
std::filesystem::path xdmf_sidecar_path(const std::filesystem::path& compliance_file);

/// Checks, before any work, that a sidecar can describe @p compliance_file:
/// its file name holds no ':' (XDMF separates the file from the dataset with
/// it) and the sidecar would not overwrite the compliance file itself.
/// @throws InputError naming the path and what to do.
void check_xdmf_sidecar_name(const std::filesystem::path& compliance_file);

/// The XDMF 3 document for a compliance file of @p model's sizes (V, T, F and
/// the material names; format 1.1: it refers to /visualization), whose
/// datasets it reaches as `<h5_file_name>:/…`.
/// @param h5_file_name the compliance file's name relative to the sidecar
///   (normally just its file name)
std::string xdmf_document(const ComplianceModel& model, const std::string& h5_file_name);

/// Writes xdmf_document() at xdmf_sidecar_path(@p compliance_file),
/// atomically (AtomicOutput): a viewer sees the previous sidecar or the new
/// one. Call it once the compliance file is in place.
/// @throws SystemError if the file cannot be written or renamed.
void write_xdmf_sidecar(const std::filesystem::path& compliance_file, const ComplianceModel& model);

}  // namespace palpate
