#include "feel/feel_compare.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <set>
#include <utility>

namespace palpate::feel {

bool FeelComparison::passed() const {
  return same_shape && worst_tool_mismatches <= tolerance.allowed_mismatches;
}

std::string FeelComparison::summary() const {
  if (!same_shape) return first_mismatch;
  return fmt::format(
      "{} of {} samples outside the tolerance (at most {} per tool allowed, worst tool {}; {} "
      "beyond the horizon not compared); max |ΔF| {:.3g} N at {:.3f} s{}{}",
      mismatches, compared, tolerance.allowed_mismatches, worst_tool_mismatches, not_compared,
      max_force_diff_n, max_force_diff_time_s,
      first_mismatch.empty() ? "" : "; first: ", first_mismatch);
}

namespace {

bool within(double diff, double reference, double abs, double rel) {
  return diff <= abs + rel * reference;
}

}  // namespace

FeelComparison compare(const FeelTrace& reference, const FeelTrace& actual,
                       const FeelTolerance& tolerance) {
  FeelComparison c;
  c.tolerance = tolerance;
  if (reference.tools != actual.tools || reference.ticks != actual.ticks) {
    c.same_shape = false;
    c.first_mismatch = fmt::format(
        "the gesture changed: reference {} ticks of {} tool(s), now {} ticks of {} tool(s)",
        reference.ticks, reference.tools.size(), actual.ticks, actual.tools.size());
    return c;
  }
  const std::size_t n_tools = actual.tools.size();
  std::vector<int> per_tool(n_tools, 0);
  std::vector<std::vector<int>> mismatch_ticks(n_tools);
  auto horizon = [&](int tool) {
    const auto k = static_cast<std::size_t>(tool);
    return k < reference.horizon.size() ? reference.horizon[k] : reference.ticks;
  };
  std::set<std::pair<int, int>> kept;  // (tick, tool) of the reference
  auto mismatch = [&](const FeelSample& s, const std::string& what) {
    ++c.mismatches;
    ++per_tool[static_cast<std::size_t>(s.tool)];
    mismatch_ticks[static_cast<std::size_t>(s.tool)].push_back(s.tick);
    if (c.first_mismatch.empty())
      c.first_mismatch =
          fmt::format("{} at {:.3f} s (tick {}): {}",
                      actual.tools[static_cast<std::size_t>(s.tool)], s.time_s, s.tick, what);
  };
  for (const FeelSample& r : reference.samples) {
    kept.insert({r.tick, r.tool});
    if (r.tick >= horizon(r.tool)) {
      ++c.not_compared;
      continue;
    }
    if (r.tick < 0 || r.tick >= actual.ticks) {
      c.same_shape = false;
      c.first_mismatch = fmt::format("reference tick {} is not in the trace", r.tick);
      return c;
    }
    const FeelSample& a =
        actual
            .samples[static_cast<std::size_t>(r.tick) * n_tools + static_cast<std::size_t>(r.tool)];
    ++c.compared;
    const double df = (a.force_n - r.force_n).norm();
    if (df > c.max_force_diff_n) {
      c.max_force_diff_n = df;
      c.max_force_diff_time_s = r.time_s;
    }
    if (a.state != r.state)
      mismatch(a, fmt::format("state {}, reference {}", tool_state_name(a.state),
                              tool_state_name(r.state)));
    else if (a.contacts != r.contacts || a.held != r.held)
      mismatch(a, fmt::format("{} contacts ({} held), reference {} ({} held)", a.contacts, a.held,
                              r.contacts, r.held));
    else if (!within(df, r.force_n.norm(), tolerance.force_abs_n, tolerance.force_rel))
      mismatch(a, fmt::format("force ({:.4f}, {:.4f}, {:.4f}) N, reference ({:.4f}, {:.4f}, "
                              "{:.4f}) N, |ΔF| {:.3g} N",
                              a.force_n.x(), a.force_n.y(), a.force_n.z(), r.force_n.x(),
                              r.force_n.y(), r.force_n.z(), df));
    else if (!within((a.torque_nm - r.torque_nm).norm(), r.torque_nm.norm(),
                     tolerance.torque_abs_nm, tolerance.torque_rel))
      mismatch(a, fmt::format("torque |ΔT| {:.3g} N·m (reference |T| {:.3g} N·m)",
                              (a.torque_nm - r.torque_nm).norm(), r.torque_nm.norm()));
    else if (!within(std::abs(a.grip_n - r.grip_n), std::abs(r.grip_n), tolerance.grip_abs_n,
                     tolerance.grip_rel))
      mismatch(a, fmt::format("grip {:.4f} N, reference {:.4f} N", a.grip_n, r.grip_n));
  }
  // Transitions the reference does not have (it keeps every one of its own).
  for (std::size_t j = n_tools; j < actual.samples.size(); ++j) {
    const FeelSample& a = actual.samples[j];
    const FeelSample& before = actual.samples[j - n_tools];
    const bool changed =
        a.state != before.state || a.contacts != before.contacts || a.held != before.held;
    if (changed && a.tick < horizon(a.tool) && !kept.count({a.tick, a.tool}))
      mismatch(a, fmt::format("a change to {} with {} contacts the reference does not have",
                              tool_state_name(a.state), a.contacts));
  }
  c.worst_tool_mismatches = *std::max_element(per_tool.begin(), per_tool.end());
  const auto allowed = static_cast<std::size_t>(tolerance.allowed_mismatches);
  for (auto& ticks : mismatch_ticks) {
    std::sort(ticks.begin(), ticks.end());
    c.failing_tick.push_back(ticks.size() > allowed ? ticks[allowed] : actual.ticks);
  }
  return c;
}

void find_horizon(FeelTrace& trace, const SurfaceModel& model, const Gesture& gesture,
                  const FeelSetup& setup, const HorizonProbe& probe,
                  const FeelTolerance& tolerance) {
  trace.horizon.assign(trace.tools.size(), trace.ticks);
  for (int seed = 1; seed <= probe.seeds; ++seed) {
    SurfaceModel perturbed = model;
    perturb_compliance(perturbed, probe.relative, static_cast<unsigned>(seed));
    const FeelComparison c = compare(trace, play(perturbed, gesture, setup), tolerance);
    for (std::size_t k = 0; k < trace.tools.size(); ++k)
      if (c.failing_tick[k] < trace.ticks)
        trace.horizon[k] =
            std::min(trace.horizon[k], std::max(0, c.failing_tick[k] - probe.margin_ticks));
  }
}

}  // namespace palpate::feel
