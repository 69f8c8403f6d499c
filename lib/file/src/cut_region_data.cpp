// The group /cut_region of the compliance file (format 1.3): writing,
// reading and checking it (docs/compliance-file.md, "The cut region").

#include "palpate/file/cut_region_data.hpp"

#include <fmt/format.h>
#include <hdf5.h>

#include <Eigen/LU>
#include <cmath>

#include "palpate/core/error.hpp"
#include "palpate/file/detail/compliance_file_internal.hpp"
#include "palpate/file/detail/dataset_io.hpp"

namespace palpate {

namespace {

// Relative asymmetry accepted in a vertex tensor K_ii: a sum of diagonal
// blocks of symmetric element stiffnesses is symmetric to round-off.
constexpr double kSymmetryTolerance = 1e-9;

[[noreturn]] void fail(const std::string& where, const char* dataset, const std::string& what) {
  throw InputError(fmt::format("{}: {}: {}", where, dataset, what));
}

template <typename Ids>
void check_range(const Ids& ids, Eigen::Index limit, const std::string& where, const char* dataset,
                 const char* of) {
  for (Eigen::Index i = 0; i < ids.size(); ++i)
    if (ids.data()[i] < 0 || ids.data()[i] >= limit)
      fail(where, dataset,
           fmt::format("entry {} is {}, outside 0..{} ({})", i, ids.data()[i], limit - 1, of));
}

void check_rows(Eigen::Index rows, Eigen::Index expected, const std::string& where,
                const char* dataset, const char* of) {
  if (rows != expected)
    fail(where, dataset, fmt::format("has {} rows, expected {} ({})", rows, expected, of));
}

template <typename Ids>
void check_increasing(const Ids& ids, const std::string& where, const char* dataset) {
  for (Eigen::Index i = 1; i < ids.size(); ++i)
    if (ids[i] <= ids[i - 1])
      fail(
          where, dataset,
          fmt::format("entry {} is not above entry {}: must be distinct and increasing", i, i - 1));
}

}  // namespace

void check_cut_region(const CutRegionData& c, Eigen::Index compliance_vertices,
                      Eigen::Index materials, const std::string& where) {
  const Eigen::Index nr = c.vertices_m.rows(), nt = c.tetrahedra.rows();
  if (nr == 0 || nt == 0) fail(where, "/cut_region", "holds no vertex or no tetrahedron");
  if (!c.vertices_m.allFinite()) fail(where, "/cut_region/vertices", "holds a non-finite value");
  check_rows(c.source_vertex_ids.size(), nr, where, "/cut_region/source_vertex_ids",
             "one per region vertex");
  check_range(c.tetrahedra, nr, where, "/cut_region/tetrahedra", "region vertices");
  for (Eigen::Index t = 0; t < nt; ++t) {
    const Eigen::RowVector3d a = c.vertices_m.row(c.tetrahedra(t, 0));
    Eigen::Matrix3d edges;
    for (int k = 0; k < 3; ++k) edges.row(k) = c.vertices_m.row(c.tetrahedra(t, k + 1)) - a;
    // NaN-safe: a degenerate or inverted element has no tensor-mass model.
    if (!(edges.determinant() > 0))
      fail(where, "/cut_region/tetrahedra",
           fmt::format("tetrahedron {} has volume {:.3g} m³: every tetrahedron must be "
                       "positively oriented, volume > 0",
                       t, edges.determinant() / 6));
  }
  check_rows(c.tet_material.size(), nt, where, "/cut_region/tetrahedron_material",
             "one per region tetrahedron");
  check_range(c.tet_material, materials, where, "/cut_region/tetrahedron_material", "materials");
  check_rows(c.element_stiffness_n_per_m.rows(), nt, where, "/cut_region/element_stiffness",
             "one per region tetrahedron");
  if (c.element_stiffness_n_per_m.cols() != kElementStiffnessValues)
    fail(where, "/cut_region/element_stiffness",
         fmt::format("has {} columns, expected {} (12 × 12, row-major)",
                     c.element_stiffness_n_per_m.cols(), kElementStiffnessValues));
  if (!c.element_stiffness_n_per_m.allFinite())
    fail(where, "/cut_region/element_stiffness", "holds a non-finite value");
  check_rows(c.vertex_stiffness_n_per_m.rows(), nr, where, "/cut_region/vertex_stiffness",
             "one per region vertex");
  if (c.vertex_stiffness_n_per_m.cols() != kTensorValues ||
      c.edge_stiffness_n_per_m.cols() != kTensorValues)
    fail(where, "/cut_region",
         "vertex_stiffness and edge_stiffness must have 9 columns (3 × 3, row-major)");
  if (!c.vertex_stiffness_n_per_m.allFinite())
    fail(where, "/cut_region/vertex_stiffness", "holds a non-finite value");
  for (Eigen::Index v = 0; v < nr; ++v) {
    Eigen::Matrix3d Kv;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) Kv(i, j) = c.vertex_stiffness_n_per_m(v, 3 * i + j);
    if (!((Kv - Kv.transpose()).norm() <= kSymmetryTolerance * Kv.norm()))
      fail(where, "/cut_region/vertex_stiffness",
           fmt::format("the tensor of region vertex {} is not symmetric", v));
  }
  check_range(c.edges, nr, where, "/cut_region/edges", "region vertices");
  for (Eigen::Index e = 0; e < c.edges.rows(); ++e)
    if (!(c.edges(e, 0) < c.edges(e, 1)) ||
        (e > 0 && !(c.edges(e - 1, 0) < c.edges(e, 0) ||
                    (c.edges(e - 1, 0) == c.edges(e, 0) && c.edges(e - 1, 1) < c.edges(e, 1)))))
      fail(where, "/cut_region/edges",
           fmt::format("edge {} ({}, {}): edges must be (i, j) with i < j, sorted, distinct", e,
                       c.edges(e, 0), c.edges(e, 1)));
  check_rows(c.edge_stiffness_n_per_m.rows(), c.edges.rows(), where, "/cut_region/edge_stiffness",
             "one per edge");
  if (!c.edge_stiffness_n_per_m.allFinite())
    fail(where, "/cut_region/edge_stiffness", "holds a non-finite value");
  check_range(c.boundary_triangles, nr, where, "/cut_region/boundary_triangles", "region vertices");
  check_range(c.interface_vertices, nr, where, "/cut_region/interface_vertices", "region vertices");
  check_rows(c.interface_compliance_index.size(), c.interface_vertices.size(), where,
             "/cut_region/interface_compliance_index", "one per interface vertex");
  check_range(c.interface_compliance_index, compliance_vertices, where,
              "/cut_region/interface_compliance_index", "/compliance/vertex_ids");
  check_increasing(c.interface_compliance_index, where, "/cut_region/interface_compliance_index");
  check_range(c.fixed_vertices, nr, where, "/cut_region/fixed_vertices", "region vertices");
  check_increasing(c.fixed_vertices, where, "/cut_region/fixed_vertices");
  if (!(c.density_kg_m3 > 0) || !std::isfinite(c.density_kg_m3))
    fail(where, "/cut_region/density_kg_m3",
         fmt::format("is {}, expected a finite number > 0 kg/m³", c.density_kg_m3));
  if (!(c.damping_per_s >= 0) || !std::isfinite(c.damping_per_s))
    fail(where, "/cut_region/damping_per_s",
         fmt::format("is {}, expected a finite number ≥ 0 1/s", c.damping_per_s));
}

namespace detail {

using hdf5::Handle;

void write_cut_region(hid_t file, const CutRegionData& c, Sha256& digest) {
  hdf5::group(file, "cut_region");
  write_matrix(file, "/cut_region/vertices", c.vertices_m, H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE,
               digest);
  write_vector(file, "/cut_region/source_vertex_ids", c.source_vertex_ids, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
  write_matrix(file, "/cut_region/tetrahedra", c.tetrahedra, H5T_NATIVE_INT, H5T_STD_I32LE, digest);
  write_vector(file, "/cut_region/tetrahedron_material", c.tet_material, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
  write_matrix(file, "/cut_region/element_stiffness", c.element_stiffness_n_per_m,
               H5T_NATIVE_DOUBLE, H5T_IEEE_F64LE, digest);
  write_matrix(file, "/cut_region/vertex_stiffness", c.vertex_stiffness_n_per_m, H5T_NATIVE_DOUBLE,
               H5T_IEEE_F64LE, digest);
  write_matrix(file, "/cut_region/edges", c.edges, H5T_NATIVE_INT, H5T_STD_I32LE, digest);
  write_matrix(file, "/cut_region/edge_stiffness", c.edge_stiffness_n_per_m, H5T_NATIVE_DOUBLE,
               H5T_IEEE_F64LE, digest);
  write_matrix(file, "/cut_region/boundary_triangles", c.boundary_triangles, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
  write_vector(file, "/cut_region/interface_vertices", c.interface_vertices, H5T_NATIVE_INT,
               H5T_STD_I32LE, digest);
  write_vector(file, "/cut_region/interface_compliance_index", c.interface_compliance_index,
               H5T_NATIVE_INT, H5T_STD_I32LE, digest);
  write_vector(file, "/cut_region/fixed_vertices", c.fixed_vertices, H5T_NATIVE_INT, H5T_STD_I32LE,
               digest);
  // Datasets, not attributes: the content digest covers datasets only.
  write_vector(file, "/cut_region/density_kg_m3",
               Eigen::VectorXd(Eigen::VectorXd::Constant(1, c.density_kg_m3)), H5T_NATIVE_DOUBLE,
               H5T_IEEE_F64LE, digest);
  write_vector(file, "/cut_region/damping_per_s",
               Eigen::VectorXd(Eigen::VectorXd::Constant(1, c.damping_per_s)), H5T_NATIVE_DOUBLE,
               H5T_IEEE_F64LE, digest);
  write_strings(file, "/cut_region/spec", {c.spec}, digest);
}

CutRegionData read_cut_region(Reader& r) {
  CutRegionData c;
  c.vertices_m = r.matrix<double, 3>("/cut_region/vertices", H5T_NATIVE_DOUBLE);
  c.source_vertex_ids = r.ints("/cut_region/source_vertex_ids");
  c.tetrahedra = r.matrix<int, 4>("/cut_region/tetrahedra", H5T_NATIVE_INT);
  c.tet_material = r.ints("/cut_region/tetrahedron_material");
  c.element_stiffness_n_per_m =
      r.matrix<double, kElementStiffnessValues>("/cut_region/element_stiffness", H5T_NATIVE_DOUBLE);
  c.vertex_stiffness_n_per_m =
      r.matrix<double, kTensorValues>("/cut_region/vertex_stiffness", H5T_NATIVE_DOUBLE);
  c.edges = r.matrix<int, 2>("/cut_region/edges", H5T_NATIVE_INT);
  c.edge_stiffness_n_per_m =
      r.matrix<double, kTensorValues>("/cut_region/edge_stiffness", H5T_NATIVE_DOUBLE);
  c.boundary_triangles = r.matrix<int, 3>("/cut_region/boundary_triangles", H5T_NATIVE_INT);
  c.interface_vertices = r.ints("/cut_region/interface_vertices");
  c.interface_compliance_index = r.ints("/cut_region/interface_compliance_index");
  c.fixed_vertices = r.ints("/cut_region/fixed_vertices");
  auto scalar = [&](const char* name) {
    const Eigen::VectorXd v = r.vector<double>(name, H5T_NATIVE_DOUBLE);
    if (v.size() != 1) r.fail(name, fmt::format("has {} values, expected one", v.size()));
    return v[0];
  };
  c.density_kg_m3 = scalar("/cut_region/density_kg_m3");
  c.damping_per_s = scalar("/cut_region/damping_per_s");
  const auto d = r.dims("/cut_region/spec", 1);
  if (d[0] != 1) r.fail("/cut_region/spec", fmt::format("has {} strings, expected one", d[0]));
  {
    Handle type = hdf5::string_type();
    char* raw = nullptr;
    r.read("/cut_region/spec", type, &raw);
    c.spec = raw ? raw : "";
    Handle set(H5Dopen2(r.root, "/cut_region/spec", H5P_DEFAULT), H5Dclose,
               "open /cut_region/spec");
    Handle space(H5Dget_space(set), H5Sclose, "get a dataspace");
    H5Dvlen_reclaim(type, space, H5P_DEFAULT, &raw);
  }
  r.hash_dataset("/cut_region/spec", d);
  r.hash(c.spec.c_str(), c.spec.size() + 1);
  return c;
}

}  // namespace detail

}  // namespace palpate
