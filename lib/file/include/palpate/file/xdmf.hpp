#pragma once
/// @file
/// The XDMF sidecars of a compliance file: small XML files next to `X.h5` that
/// describe its meshes and per-vertex arrays to viewers (ParaView's Xdmf3
/// reader, VisIt) and to meshio.read: `X.xdmf`, the tetrahedral volume, and
/// `X.surface.xdmf`, the boundary triangles. Each is one Uniform grid, the
/// subset of XDMF that meshio reads (one grid per file, no collection). They
/// hold no numbers themselves: every array is a reference `X.h5:/dataset`, by
/// file name relative to the sidecar's directory, so the files move together.
/// Layout: docs/compliance-file.md, "The XDMF sidecar".

#include <filesystem>
#include <string>

#include "palpate/file/compliance_file.hpp"

namespace palpate {

/// The volume sidecar of @p compliance_file: same directory and stem,
/// extension `.xdmf` (`organ.h5` → `organ.xdmf`). The one the report names.
std::filesystem::path xdmf_sidecar_path(const std::filesystem::path& compliance_file);

/// The surface sidecar of @p compliance_file: same directory and stem,
/// extension `.surface.xdmf` (`organ.h5` → `organ.surface.xdmf`).
std::filesystem::path xdmf_surface_sidecar_path(const std::filesystem::path& compliance_file);

/// Checks, before any work, that sidecars can describe @p compliance_file:
/// its file name is valid UTF-8 without control characters, holds no ':'
/// (XDMF separates the file from the dataset with it), and the volume
/// sidecar would not overwrite the compliance file itself (the surface
/// sidecar cannot: its name has one extension more than the file's stem).
/// @throws InputError naming the path and what to do.
void check_xdmf_sidecar_name(const std::filesystem::path& compliance_file);

/// The XDMF 3 document of the volume sidecar for a compliance file of
/// @p model's sizes (V, T and the material names, listed in its comment;
/// format 1.1: it refers to /visualization): one Uniform grid "volume" of the
/// T tetrahedra on the V vertices (metres), the cell array `material` and the
/// node arrays `softness_m_per_n` (m/N), `fixed` (int8) and
/// `source_vertex_id`. It reaches the datasets as `<h5_file_name>:/…`.
/// @param h5_file_name the compliance file's name relative to the sidecar
///   (normally just its file name)
std::string xdmf_document(const ComplianceModel& model, const std::string& h5_file_name);

/// The XDMF 3 document of the surface sidecar: one Uniform grid "surface" of
/// the F boundary triangles on all V vertices, with the same node arrays as
/// xdmf_document() and no cell array. Same @p h5_file_name.
std::string xdmf_surface_document(const ComplianceModel& model, const std::string& h5_file_name);

/// Writes xdmf_document() at xdmf_sidecar_path(@p compliance_file), then
/// xdmf_surface_document() at xdmf_surface_sidecar_path(), each atomically
/// (AtomicOutput): a viewer sees the previous sidecar or the new one. Call it
/// once the compliance file is in place.
/// @throws SystemError if a file cannot be written or renamed.
void write_xdmf_sidecar(const std::filesystem::path& compliance_file, const ComplianceModel& model);

}  // namespace palpate
