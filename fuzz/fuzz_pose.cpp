// Pose validation and the contact engine: ToolContactEngine::check, then
// update for the poses it takes, and watchdog, as palpated's tool loop
// drives them (service.cpp), with fuzzed pose streams of two tools on a small
// real model. The engine promises no exceptions; every refused pose a
// PoseProblem; every output finite, within the tool's force limit.

#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "fuzz_support.hpp"
#include "palpate/runtime/tool_contact.hpp"

namespace {

using palpate::PoseProblem;
using palpate::RequestStatus;
using palpate::ToolContactEngine;

double special(FuzzedDataProvider& in) {
  static constexpr double kSpecial[] = {0.0,
                                        -0.0,
                                        1e-300,
                                        4.9e-324,
                                        1e300,
                                        std::numeric_limits<double>::max(),
                                        std::numeric_limits<double>::infinity(),
                                        -std::numeric_limits<double>::infinity(),
                                        std::numeric_limits<double>::quiet_NaN()};
  return in.PickValueInArray(kSpecial);
}

// A coordinate near the organ (the box spans [0, 0.1] × [0, 0.05] × [0, 0.04] m)
// most of the time, anything sometimes.
double coordinate(FuzzedDataProvider& in, double lo, double hi) {
  switch (in.ConsumeIntegralInRange(0, 7)) {
    case 0:
      return special(in);
    case 1:
      return in.ConsumeFloatingPoint<double>();
    default:
      return in.ConsumeFloatingPointInRange(lo, hi);
  }
}

palpate::ToolPoseInput pose(FuzzedDataProvider& in, std::uint64_t* sequence) {
  palpate::ToolPoseInput p;
  *sequence += in.ConsumeIntegralInRange(0, 3) == 0 ? in.ConsumeIntegral<std::uint8_t>() : 1;
  p.sequence =
      in.ConsumeIntegralInRange(0, 31) == 0 ? in.ConsumeIntegral<std::uint64_t>() : *sequence;
  p.send_time_ns = in.ConsumeIntegral<std::int64_t>();
  p.position_m = {coordinate(in, -0.02, 0.12), coordinate(in, -0.02, 0.07),
                  coordinate(in, -0.01, 0.06)};
  Eigen::Vector4d q{coordinate(in, -1, 1), coordinate(in, -1, 1), coordinate(in, -1, 1),
                    coordinate(in, -1, 1)};
  // Mostly a unit quaternion (a device's), sometimes as sent.
  if (in.ConsumeBool() && q.allFinite() && q.norm() > 1e-6) q.normalize();
  p.orientation = Eigen::Quaterniond(q[3], q[0], q[1], q[2]);
  p.jaw_angle_rad = coordinate(in, -0.1, 1.5);
  return p;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const palpate::SurfaceModel& model = palpate::fuzz::box_model();
  FuzzedDataProvider in(data, size);

  std::vector<palpate::ToolGeometry> tools(2);
  tools[0].id = "left";
  tools[1].id = "right";
  tools[1].tip = palpate::TipShape::kSphere;
  tools[1].tip_length_m = 0;
  tools[1].tip_radius_m = in.ConsumeFloatingPointInRange(0.001, 0.03);
  tools[1].friction = in.PickValueInArray({0.0, 0.3, std::numeric_limits<double>::infinity()});
  palpate::ContactSettings settings;
  settings.max_contacts_per_tool = in.ConsumeIntegralInRange(1, 24);
  settings.max_iterations = in.ConsumeIntegralInRange(1, 4);
  palpate::SolverLimits limits;
  limits.max_constraints = in.ConsumeIntegralInRange(2, 64);
  ToolContactEngine engine(model, tools, settings, limits);

  std::uint64_t sequence[2] = {0, 0};
  double now_s = 0;
  for (int tick = 0; tick < 64 && in.remaining_bytes() > 0; ++tick) {
    // The loop's clock is monotonic: ticks of about 1 ms, sometimes a gap
    // long enough for the watchdog.
    now_s +=
        in.ConsumeIntegralInRange(0, 15) == 0 ? in.ConsumeFloatingPointInRange(0.0, 0.5) : 0.001;
    if (in.ConsumeIntegralInRange(0, 7) == 0) {
      const std::uint64_t changed = engine.watchdog(now_s);
      PALPATE_FUZZ_CHECK(changed < 4);
      continue;
    }
    const int t = in.ConsumeIntegralInRange(0, 1);
    palpate::ToolPoseInput p = pose(in, &sequence[t]);
    if (engine.check(t, p) != PoseProblem::kNone) continue;
    PALPATE_FUZZ_CHECK(std::abs(p.orientation.norm() - 1) < 1e-9);
    const RequestStatus status = engine.update(t, p, now_s);
    if (status != RequestStatus::kOk) PALPATE_FUZZ_CHECK(engine.solver_message()[0] != '\0');

    const palpate::ToolOutput& out = engine.output(t);
    PALPATE_FUZZ_CHECK(out.force_n.allFinite() && out.torque_nm.allFinite());
    PALPATE_FUZZ_CHECK(std::isfinite(out.grip_n) && out.grip_n >= 0);
    PALPATE_FUZZ_CHECK(out.force_n.norm() <= engine.tool(t).force_limit_n * (1 + 1e-9));
    PALPATE_FUZZ_CHECK(out.held >= 0 && out.held <= out.contacts);
    PALPATE_FUZZ_CHECK(out.event_count >= 0 &&
                       out.event_count <= static_cast<int>(out.events.size()));
    const auto indices = engine.contact_indices();
    // Each point loads up to three vertices (a point of a triangle).
    PALPATE_FUZZ_CHECK(static_cast<int>(engine.contact_points().size()) <= limits.max_constraints);
    PALPATE_FUZZ_CHECK(static_cast<int>(indices.size()) <= 3 * limits.max_constraints);
    PALPATE_FUZZ_CHECK(engine.contact_forces().size() == 3 * indices.size());
    for (const double f : engine.contact_forces()) PALPATE_FUZZ_CHECK(std::isfinite(f));
    for (const palpate::ContactPoint& c : engine.contact_points()) {
      PALPATE_FUZZ_CHECK(c.position_m.allFinite() && c.force_n.allFinite());
      double weight_sum = 0;
      for (int k = 0; k < c.vertex_count; ++k) weight_sum += c.weights[k];
      PALPATE_FUZZ_CHECK(c.vertex_count >= 1 && c.vertex_count <= 3);
      PALPATE_FUZZ_CHECK(std::abs(weight_sum - 1) < 1e-9);
    }
    for (const int j : indices) PALPATE_FUZZ_CHECK(j >= 0 && j < model.compliance_vertex_count());
  }
  return 0;
}
