// The feel under regression tests (docs/tools.md, "The feel under regression
// tests"): every gesture of config/gestures/ for palpated's default tools,
// played in process on the sample organ with those tools, must feel as its reference trace in
// tests/feel/reference/, within FeelTolerance (feel_compare.hpp). And the
// tolerance is shown to sit between round-off and physics: a compliance
// perturbed far beyond round-off is accepted, a 2 % stiffer organ, a
// friction of 0.31 instead of 0.3 and a gesture moved by 1 mm are rejected.
//
// The organ: PALPATE_FEEL_MODEL (tests/feel/make_organ.sh, a CTest fixture).

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include "feel/feel_compare.hpp"
#include "feel/feel_trace.hpp"
#include "palpate/core/error.hpp"
#include "support/expect_error.hpp"

namespace palpate::feel {
namespace {

namespace fs = std::filesystem;

const fs::path kSource = PALPATE_SOURCE_DIR;
const fs::path kGestures = kSource / "config" / "gestures";
const fs::path kReferences = kSource / "tests" / "feel" / "reference";

class FeelTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (const char* path = std::getenv("PALPATE_FEEL_MODEL"))
      model_ = new SurfaceModel(load_surface_model("organ", path));
  }
  void SetUp() override {
    ASSERT_NE(model_, nullptr) << "PALPATE_FEEL_MODEL: the organ of tests/feel/make_organ.sh "
                                  "(CTest sets it: ctest -R feel_)";
  }
  static void TearDownTestSuite() {
    delete model_;
    model_ = nullptr;
  }
  static const SurfaceModel& model() { return *model_; }

  /// The stems of the gesture files for palpated's default tools, sorted. A
  /// gesture for other tools (cut.toml's cutting hook, on a model served
  /// with its cut region) is played where those are served
  /// (tests/daemon/cut_gesture_dds_test.cpp).
  static std::vector<std::string> gestures() {
    std::set<std::string> names;
    const FeelSetup defaults = FeelSetup::palpated_defaults();
    for (const auto& entry : fs::directory_iterator(kGestures)) {
      if (entry.path().extension() != ".toml") continue;
      const Gesture g = read_gesture_file(entry.path());
      if (std::all_of(g.tools.begin(), g.tools.end(), [&](const GestureTool& t) {
            return std::any_of(defaults.tools.begin(), defaults.tools.end(),
                               [&](const ToolGeometry& d) { return d.id == t.id; });
          }))
        names.insert(entry.path().stem().string());
    }
    return {names.begin(), names.end()};
  }
  static Gesture gesture(const std::string& name) {
    return read_gesture_file(kGestures / (name + ".toml"));
  }
  /// @p name played on @p organ with @p setup against its reference.
  static FeelComparison against_reference(const std::string& name, const SurfaceModel& organ,
                                          const FeelSetup& setup = FeelSetup::palpated_defaults()) {
    return against_reference(name, gesture(name), organ, setup);
  }
  static FeelComparison against_reference(const std::string& name, const Gesture& g,
                                          const SurfaceModel& organ,
                                          const FeelSetup& setup = FeelSetup::palpated_defaults()) {
    return compare(read_csv(kReferences / (name + ".csv")), play(organ, g, setup));
  }

 private:
  static SurfaceModel* model_;
};
SurfaceModel* FeelTest::model_ = nullptr;

// The gestures whose reference is compared to its end (the others are cut
// by their horizon, below), for the perturbations.
const std::vector<std::string> kWhole = {"glide", "grasp-pull-release", "lift", "press",
                                         "two-handed"};

TEST_F(FeelTest, EveryGestureHasAReferenceTrace) {
  const auto names = gestures();
  ASSERT_GE(names.size(), 7u);
  for (const auto& name : names)
    EXPECT_TRUE(fs::exists(kReferences / (name + ".csv")))
        << name << ": no reference trace; run scripts/regenerate-feel-traces.sh";
}

// Where round-off alone changes a trace beyond the tolerance, its reference
// stops being compared (its horizon, find_horizon()). With the current
// engine no gesture is cut: every trace is compared to its end. (Until
// friction slid onto its cone's edge, 2026-11-27, demo and steady-press
// were cut right after the first touch: a sticking contact left its cone
// and lost its whole tangential force on a decision whose margin was
// round-off, and steady-press's right tool lost its contact 3-5 mm deep
// for a round-off dependent time; what they felt after that differed
// between two BLAS kernels by up to 1.6 N.) A regeneration that cuts a
// gesture fails here: look at it, then update the list.
TEST_F(FeelTest, OnlyTheKnownGesturesAreCutByRoundOff) {
  std::vector<std::string> cut;
  for (const auto& name : gestures()) {
    const FeelTrace reference = read_csv(kReferences / (name + ".csv"));
    for (std::size_t k = 0; k < reference.tools.size(); ++k)
      if (reference.horizon[k] < reference.ticks) {
        cut.push_back(name);
        std::printf("  %-14s %-6s compared until %.3f s of %.3f s\n", name.c_str(),
                    reference.tools[k].c_str(), reference.horizon[k] * 1e-3,
                    reference.ticks * 1e-3);
      }
  }
  cut.erase(std::unique(cut.begin(), cut.end()), cut.end());
  EXPECT_EQ(cut, std::vector<std::string>{});
}

TEST_F(FeelTest, EveryGestureFeelsAsItsReference) {
  for (const auto& name : gestures()) {
    const FeelComparison c = against_reference(name, model());
    EXPECT_TRUE(c.passed()) << name << ": " << c.summary()
                            << "\nIf this change of the feel is meant: "
                               "scripts/regenerate-feel-traces.sh (docs/tools.md)";
    EXPECT_GT(c.compared, 0) << name;
    std::printf("  %-20s %s\n", name.c_str(), c.summary().c_str());
  }
}

// Round-off: a different BLAS kernel moves G by ~5e-14 relative (this
// organ precomputed with OPENBLAS_CORETYPE=Prescott or Haswell instead of
// the machine's own kernel). Each entry of G moved by up to 1e-12 relative
// (symmetric; seeds other than those that set the references' horizons)
// must pass, every gesture.
TEST_F(FeelTest, RoundOffInTheComplianceIsAccepted) {
  SurfaceModel noisy = model();
  perturb_compliance(noisy, 1e-12, 101);
  for (const auto& name : gestures()) {
    const FeelComparison c = against_reference(name, noisy);
    EXPECT_TRUE(c.passed()) << name << ": " << c.summary();
    std::printf("  G ± 1e-12  %-20s %s\n", name.c_str(), c.summary().c_str());
  }
}

// E × 1.02 (linear elasticity, same ν: G / 1.02): every force 2 % larger.
TEST_F(FeelTest, AStifferOrganIsRejected) {
  SurfaceModel stiffer = model();
  stiffer.G /= 1.02;
  for (const auto& name : kWhole) {
    const FeelComparison c = against_reference(name, stiffer);
    EXPECT_FALSE(c.passed()) << name << ": a 2 % stiffer organ passed: " << c.summary();
    std::printf("  E x 1.02   %-20s %s\n", name.c_str(), c.summary().c_str());
  }
}

// Friction 0.3 → 0.31 changes the force wherever a contact slides (its
// tangential force is μ × its normal force). A press along the normal and a
// grasp never slide: there the feel does not depend on μ, and the trace
// must not change.
TEST_F(FeelTest, MoreFrictionIsRejectedWhereTheTipSlides) {
  FeelSetup setup = FeelSetup::palpated_defaults();
  for (auto& tool : setup.tools) tool.friction = 0.31;
  for (const auto& name : {"glide", "two-handed"}) {
    const FeelComparison c = against_reference(name, model(), setup);
    EXPECT_FALSE(c.passed()) << name << ": friction 0.31 passed: " << c.summary();
    std::printf("  mu 0.31    %-20s %s\n", name, c.summary().c_str());
  }
  for (const auto& name : {"press", "grasp-pull-release"}) {
    const FeelComparison c = against_reference(name, model(), setup);
    EXPECT_TRUE(c.passed()) << name << ": " << c.summary();
  }
}

// Every keyframe 1 mm further along the anchor's x tangent: the same gesture
// on another spot of the organ.
TEST_F(FeelTest, AGestureMovedBy1MillimetreIsRejected) {
  for (const auto& name : kWhole) {
    Gesture moved = gesture(name);
    for (auto& tool : moved.tools)
      for (auto& key : tool.keyframes) key.tip_m.x() += 0.001;
    const FeelComparison c = against_reference(name, moved, model());
    EXPECT_FALSE(c.passed()) << name << ": moved 1 mm, passed: " << c.summary();
    std::printf("  moved 1 mm %-20s %s\n", name.c_str(), c.summary().c_str());
  }
}

TEST(FeelTraceFile, ABadTraceGetsOneMessage) {
  const fs::path dir = fs::temp_directory_path() / "palpate-feel-trace-test";
  fs::create_directories(dir);
  testing::expect_error<InputError>([&] { read_csv(dir / "missing.csv"); },
                                    {"missing.csv", "regenerate-feel-traces.sh"});
  {
    std::ofstream out(dir / "bad.csv");
    out << "# gesture press\n# ticks 3\n# stride 1\n# tools left\n"
           "tick,time_s,tool,fx_n,fy_n,fz_n,tx_nm,ty_nm,tz_nm,grip_n,contacts,held,state\n"
           "0,0.000,left,0,0,0,0,0,0,0,0,0,free\n"
           "1,0.001,left,0,0,0,0,0,0,0,0,0,floating\n";
  }
  testing::expect_error<InputError>([&] { read_csv(dir / "bad.csv"); },
                                    {"bad.csv:7: state 'floating'", "accepted: free"});
  fs::remove_all(dir);
}

}  // namespace
}  // namespace palpate::feel
