// Request validation: ConstraintSolver::begin/add/solve as palpated's
// request handler drives them (service.cpp), with fuzzed constraint lists on
// a small real model. The solver promises no exceptions, a status for every
// failure, and on kOk finite forces and displacements, the given forces
// returned unchanged.

#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "fuzz_support.hpp"
#include "palpate/runtime/constraint_solver.hpp"

namespace {

using palpate::ConstraintKind;
using palpate::ConstraintSolver;
using palpate::RequestStatus;

// Numbers a client could send: ordinary ones, the edges of double, and raw bits.
double number(FuzzedDataProvider& in) {
  static constexpr double kSpecial[] = {0.0,
                                        -0.0,
                                        1e-3,
                                        -1e-3,
                                        0.01,
                                        1.0,
                                        -5.0,
                                        1e-300,
                                        4.9e-324,
                                        1e300,
                                        -1e308,
                                        std::numeric_limits<double>::max(),
                                        std::numeric_limits<double>::infinity(),
                                        -std::numeric_limits<double>::infinity(),
                                        std::numeric_limits<double>::quiet_NaN()};
  switch (in.ConsumeIntegralInRange(0, 3)) {
    case 0:
      return in.PickValueInArray(kSpecial);
    case 1:
      return in.ConsumeFloatingPointInRange(-0.05, 0.05);  // millimetre pokes
    case 2:
      return in.ConsumeFloatingPointInRange(-20.0, 20.0);  // forces a hand gives
    default:
      return in.ConsumeFloatingPoint<double>();
  }
}

// A vertex id: mostly the model's own (compliance, fixed, interior), sometimes any.
std::uint32_t vertex_id(FuzzedDataProvider& in, const palpate::SurfaceModel& model) {
  const std::uint32_t n = model.mesh_vertex_count();
  if (in.ConsumeIntegralInRange(0, 7) == 0) return in.ConsumeIntegral<std::uint32_t>();
  return in.ConsumeIntegralInRange<std::uint32_t>(0, n - 1);
}

bool finite(Eigen::Map<const Eigen::VectorXd> v) { return v.allFinite(); }

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const palpate::SurfaceModel& model = palpate::fuzz::box_model();
  FuzzedDataProvider in(data, size);
  palpate::SolverLimits limits;
  limits.max_constraints = 8;
  limits.cache_slots = in.ConsumeIntegralInRange(1, 3);
  limits.max_condition = in.ConsumeBool() ? 1e12 : in.ConsumeFloatingPointInRange(1.0, 1e18);
  ConstraintSolver solver(model, limits);
  Eigen::VectorXd surface(model.G.rows());

  // Several requests on one solver: its factorization cache and its epochs
  // must not carry anything wrong from one request to the next.
  while (in.remaining_bytes() > 0) {
    struct Constraint {
      std::uint32_t vertex;
      std::int32_t kind;
      double value[3], normal[3];
    };
    std::size_t count = in.ConsumeIntegralInRange<std::size_t>(0, 10);
    if (in.ConsumeIntegralInRange(0, 31) == 0) count = in.ConsumeIntegral<std::size_t>();
    const std::size_t made = std::min<std::size_t>(count, 10);
    std::vector<Constraint> constraints(made);
    for (auto& c : constraints) {
      c.vertex = vertex_id(in, model);
      c.kind = in.ConsumeIntegralInRange(0, 15) == 0 ? in.ConsumeIntegral<std::int32_t>()
                                                     : in.ConsumeIntegralInRange(0, 2);
      for (double& v : c.value) v = number(in);
      for (double& v : c.normal) v = number(in);
    }

    RequestStatus status = solver.begin(count);
    if (count > static_cast<std::size_t>(limits.max_constraints)) {
      PALPATE_FUZZ_CHECK(status == RequestStatus::kTooManyConstraints);
      continue;
    }
    for (std::size_t j = 0; j < count && status == RequestStatus::kOk; ++j)
      status = solver.add(constraints[j].vertex, constraints[j].kind, constraints[j].value,
                          constraints[j].normal);
    if (status == RequestStatus::kOk) status = solver.solve();
    if (status != RequestStatus::kOk) {
      PALPATE_FUZZ_CHECK(solver.message()[0] != '\0');
      continue;
    }

    PALPATE_FUZZ_CHECK(solver.size() == static_cast<int>(count));
    PALPATE_FUZZ_CHECK(finite(solver.forces()));
    PALPATE_FUZZ_CHECK(finite(solver.displacements()));
    PALPATE_FUZZ_CHECK(solver.total_force().allFinite());
    for (std::size_t j = 0; j < count; ++j)
      if (constraints[j].kind == static_cast<std::int32_t>(ConstraintKind::kForce))
        for (int d = 0; d < 3; ++d)
          PALPATE_FUZZ_CHECK(solver.forces()[static_cast<Eigen::Index>(3 * j) + d] ==
                             constraints[j].value[d]);
    solver.surface_displacement(surface);
    PALPATE_FUZZ_CHECK(surface.allFinite());
  }
  return 0;
}
