// The cut region's fields on the wire (appended 2026-11-26; docs/dds.md, "The
// cut region"): ModelDescription.cut_region names the served region, a
// surface sample views the region's arrays without copying or allocating
// and a client reads them back, and the types stay appendable both ways: a
// reader of the layout before these fields reads a newer sample (and skips
// them), a newer reader reads an older sample (version 0, no region). The
// older layout is tests/transport/before_region.idl; samples go through
// Cyclone's own CDR stream (XCDR2, as DDS sends appendable types), no
// participant.

#include <dds/ddsi/ddsi_cdrstream.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "before_region.h"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/transport/wire.hpp"
#include "support/allocation_counter.hpp"

namespace palpate {
namespace {

using wire::bounded;
using wire::copy_bounded;

constexpr std::uint32_t kXcdr2 = 2;  // the encoding of @appendable types

/// @p sample of the type whose serialization program is @p write_ops, read
/// back into @p out as the type of @p read_ops (through XCDR2 bytes, as a
/// DDS reader of that type gets them). Free @p out with dds_stream_free_sample.
void transcode(const void* sample, const dds_topic_descriptor_t& written,
               const dds_topic_descriptor_t& read, void* out) {
  dds_ostream_t os;
  dds_ostream_init(&os, 0, kXcdr2);
  dds_stream_write(&os, static_cast<const char*>(sample), written.m_ops);
  dds_istream_t is;
  dds_istream_init(&is, os.m_index, os.m_buffer, kXcdr2);
  dds_stream_read(&is, static_cast<char*>(out), read.m_ops);
  dds_istream_fini(&is);
  dds_ostream_fini(&os);
}

SurfaceModel model_with_region() {
  SurfaceModel m;
  m.id = "liver";
  m.material_summary = "organ: E = 85000 Pa, nu = 0.45";
  m.input_hash = "sha256:" + std::string(64, 'd');
  m.G = Eigen::MatrixXd::Identity(6, 6);
  m.surface.compliance_vertex_count = 2;
  m.surface.vertex_ids = {4, 9, 1};
  m.surface.rest_positions_m = {0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09};
  m.surface.triangles = {0, 1, 2, 2, 1, 0};
  m.cut_region_spec = "box [0.01, 0.02, 0.03] to [0.04, 0.05, 0.06] m";
  return m;
}

// A region of 4 vertices, 2 visible triangles, covering drawn triangle 1.
struct RegionArrays {
  std::vector<double> positions{0, 0, 0, 0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01};
  std::vector<std::uint32_t> triangles{0, 2, 1, 1, 2, 3};
  std::vector<std::uint32_t> hidden{1};
};

// ---- palpate_model ----------------------------------------------------------------

TEST(WireRegion, TheDescriptionNamesTheRegionOnlyWhenItIsServed) {
  const SurfaceModel model = model_with_region();
  const palpate_ModelDescription served = wire::describe(model, 0.03, 50, false, true);
  EXPECT_EQ(bounded(served.cut_region), model.cut_region_spec);
  EXPECT_EQ(wire::from_idl(served).cut_region, model.cut_region_spec);
  EXPECT_EQ(wire::from_idl(served).mechanics, "linear");

  // Not simulated (palpated serves the rest alone): nothing to draw.
  const palpate_ModelDescription rest_only = wire::describe(model, 0.03, 50);
  EXPECT_EQ(bounded(rest_only.cut_region), "");
  EXPECT_EQ(wire::from_idl(rest_only).cut_region, "");

  // A spec longer than the field is cut to its 255 characters.
  SurfaceModel long_spec = model_with_region();
  long_spec.cut_region_spec = std::string(300, 's');
  EXPECT_EQ(bounded(wire::describe(long_spec, 0.03, 50, true, true).cut_region),
            std::string(255, 's'));
}

TEST(WireRegion, DescriptionsCrossTheLayoutBeforeTheRegionBothWays) {
  const SurfaceModel model = model_with_region();
  const palpate_ModelDescription newer = wire::describe(model, 0.03, 50, true, true);

  // An older reader gets every field it knows.
  palpate_before_region_ModelDescription old_read{};
  transcode(&newer, palpate_ModelDescription_desc, palpate_before_region_ModelDescription_desc,
            &old_read);
  EXPECT_EQ(bounded(old_read.model_id), "liver");
  EXPECT_EQ(bounded(old_read.mechanics), "warped");
  EXPECT_EQ(old_read.max_force, 50);
  ASSERT_EQ(old_read.triangles._length, 6u);
  EXPECT_EQ(old_read.triangles._buffer[5], 0u);
  dds_stream_free_sample(&old_read, palpate_before_region_ModelDescription_desc.m_ops);

  // A newer reader of an older palpated's description: no region.
  palpate_before_region_ModelDescription older{};
  std::memcpy(&older, &newer, sizeof older);  // the same fields, in the same order, first
  palpate_ModelDescription new_read{};
  transcode(&older, palpate_before_region_ModelDescription_desc, palpate_ModelDescription_desc,
            &new_read);
  const ModelInfo info = wire::from_idl(new_read);
  EXPECT_EQ(info.model_id, "liver");
  EXPECT_EQ(info.surface.rest_positions_m, model.surface.rest_positions_m);
  EXPECT_EQ(info.cut_region, "");
  dds_stream_free_sample(&new_read, palpate_ModelDescription_desc.m_ops);
}

// ---- palpate_surface ---------------------------------------------------------------

TEST(WireRegion, ASurfaceSampleViewsTheRegionAndAClientCopiesIt) {
  const RegionArrays r;
  palpate_SurfaceDisplacement s{};
  copy_bounded(s.model_id, "liver");
  wire::view_region(7, r.positions, r.triangles, r.hidden, s);
  EXPECT_EQ(s.topology_version, 7u);
  // Views, not copies: Cyclone must not free them.
  EXPECT_EQ(s.region_positions._buffer, r.positions.data());
  EXPECT_EQ(s.region_triangles._buffer, r.triangles.data());
  EXPECT_EQ(s.hidden_triangles._buffer, r.hidden.data());
  EXPECT_EQ(s.region_positions._length, 12u);
  EXPECT_EQ(s.region_triangles._length, 6u);
  EXPECT_EQ(s.hidden_triangles._length, 1u);
  EXPECT_FALSE(s.region_positions._release);
  EXPECT_FALSE(s.region_triangles._release);
  EXPECT_FALSE(s.hidden_triangles._release);

  const SurfaceSample sample = wire::from_idl(s);
  EXPECT_EQ(sample.topology_version, 7u);
  EXPECT_EQ(sample.region_positions_m, r.positions);
  EXPECT_EQ(sample.region_triangles, r.triangles);
  EXPECT_EQ(sample.hidden_triangles, r.hidden);

  // A model without a served region: version 0, nothing.
  palpate_SurfaceDisplacement plain{};
  wire::view_region(0, {}, {}, {}, plain);
  const SurfaceSample none = wire::from_idl(plain);
  EXPECT_EQ(none.topology_version, 0u);
  EXPECT_TRUE(none.region_positions_m.empty());
  EXPECT_TRUE(none.region_triangles.empty());
  EXPECT_TRUE(none.hidden_triangles.empty());
}

TEST(WireRegion, SurfaceSamplesCrossTheLayoutBeforeTheRegionBothWays) {
  const RegionArrays r;
  std::vector<double> displacement{1e-3, 0, -2e-3, 0, 5e-4, 0};
  std::vector<std::uint32_t> constrained{9};
  std::vector<double> forces{0, 0, -0.5};
  palpate_SurfaceContact contact{};
  copy_bounded(contact.tool_id, "grasper-left");
  contact.vertices[0] = 9;
  contact.vertices[1] = contact.vertices[2] = SurfaceContactSample::kNoVertex;
  contact.weights[0] = 1;
  contact.force[2] = -0.5;
  palpate_SurfaceDisplacement newer{};
  copy_bounded(newer.model_id, "liver");
  copy_bounded(newer.source_client_id, "tool:grasper-left");
  newer.sequence_number = 41;
  newer.total_force[2] = -0.5;
  wire::view(newer.displacement, std::span(displacement));
  wire::view(newer.constrained_vertices, std::span(constrained));
  wire::view(newer.constrained_forces, std::span(forces));
  wire::view(newer.contact_points, std::span(&contact, 1));
  wire::view_region(3, r.positions, r.triangles, r.hidden, newer);

  // The newer layout to itself: every region field survives.
  palpate_SurfaceDisplacement same{};
  transcode(&newer, palpate_SurfaceDisplacement_desc, palpate_SurfaceDisplacement_desc, &same);
  const SurfaceSample round = wire::from_idl(same);
  EXPECT_EQ(round.topology_version, 3u);
  EXPECT_EQ(round.region_positions_m, r.positions);
  EXPECT_EQ(round.region_triangles, r.triangles);
  EXPECT_EQ(round.hidden_triangles, r.hidden);
  EXPECT_EQ(round.displacement_m, displacement);
  ASSERT_EQ(round.contact_points.size(), 1u);
  EXPECT_EQ(round.contact_points[0].tool_id, "grasper-left");
  dds_stream_free_sample(&same, palpate_SurfaceDisplacement_desc.m_ops);

  // An older reader (a viewer or client built before the fields) reads the
  // fields it knows and skips the region.
  palpate_before_region_SurfaceDisplacement old_read{};
  transcode(&newer, palpate_SurfaceDisplacement_desc,
            palpate_before_region_SurfaceDisplacement_desc, &old_read);
  EXPECT_EQ(bounded(old_read.model_id), "liver");
  EXPECT_EQ(bounded(old_read.source_client_id), "tool:grasper-left");
  EXPECT_EQ(old_read.sequence_number, 41u);
  EXPECT_EQ(old_read.total_force[2], -0.5);
  ASSERT_EQ(old_read.displacement._length, 6u);
  EXPECT_EQ(std::vector<double>(old_read.displacement._buffer, old_read.displacement._buffer + 6),
            displacement);
  ASSERT_EQ(old_read.constrained_vertices._length, 1u);
  EXPECT_EQ(old_read.constrained_vertices._buffer[0], 9u);
  ASSERT_EQ(old_read.contact_points._length, 1u);
  EXPECT_EQ(bounded(old_read.contact_points._buffer[0].tool_id), "grasper-left");
  EXPECT_EQ(old_read.contact_points._buffer[0].force[2], -0.5);
  dds_stream_free_sample(&old_read, palpate_before_region_SurfaceDisplacement_desc.m_ops);

  // A newer reader of an older palpated's sample: version 0, no region.
  palpate_before_region_SurfaceDisplacement older{};
  std::memcpy(&older, &newer, sizeof older);  // the same fields, in the same order, first
  palpate_SurfaceDisplacement new_read{};
  transcode(&older, palpate_before_region_SurfaceDisplacement_desc,
            palpate_SurfaceDisplacement_desc, &new_read);
  const SurfaceSample from_older = wire::from_idl(new_read);
  EXPECT_EQ(from_older.sequence_number, 41u);
  EXPECT_EQ(from_older.displacement_m, displacement);
  ASSERT_EQ(from_older.contact_points.size(), 1u);
  EXPECT_EQ(from_older.topology_version, 0u);
  EXPECT_TRUE(from_older.region_positions_m.empty());
  EXPECT_TRUE(from_older.region_triangles.empty());
  EXPECT_TRUE(from_older.hidden_triangles.empty());
  dds_stream_free_sample(&new_read, palpate_SurfaceDisplacement_desc.m_ops);
}

TEST(WireRegion, ViewingTheRegionAllocatesNothing) {
  const RegionArrays r;
  palpate_SurfaceDisplacement s{};
  for (int i = 0; i < 3; ++i) wire::view_region(1, r.positions, r.triangles, r.hidden, s);
  const std::uint64_t before = testing::allocations_here();
  for (std::uint64_t i = 0; i < 100; ++i)
    wire::view_region(i, r.positions, r.triangles, r.hidden, s);
  EXPECT_EQ(testing::allocations_here() - before, 0u);
  EXPECT_EQ(s.topology_version, 99u);
}

}  // namespace
}  // namespace palpate
