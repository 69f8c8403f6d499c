// palpated end to end: the real daemon binary, real Cyclone DDS on loopback,
// compliance files made by the real precompute. CTest runs this executable
// inside a private network namespace (tests/CMakeLists.txt), and palpated and
// the clients use their loopback-only default configuration as well.
//
// Replies are checked against dense computations on G read from the HDF5
// file, independently of the daemon's solver.

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Dense>
#include <chrono>
#include <fstream>
#include <limits>
#include <sstream>
#include <thread>

#include "palpate/file/compliance_file.hpp"
#include "palpate/runtime/rotation_field.hpp"
#include "palpate/runtime/surface_model.hpp"
#include "palpate/runtime/warped_solver.hpp"
#include "palpate/transport/client.hpp"
#include "support/box_job.hpp"
#include "support/daemon_process.hpp"
#include "support/test_meshes.hpp"

namespace palpate {
namespace {

using namespace std::chrono_literals;
using testing::Daemon;
using testing::TempDir;

// Small well-conditioned systems on G of order 1e-4 m/N: the daemon and the
// dense reference agree to ~1e-13 relative; 1e-9 leaves margin.
constexpr double kDdsTolerance = 1e-9;
constexpr auto kDdsTimeout = 10s;

/// G and the compliance order of a file, for the dense references.
struct Reference {
  Eigen::MatrixXd G;
  std::vector<int> compliance_index;  // per mesh vertex, -1 if none

  explicit Reference(const std::filesystem::path& file) {
    const ComplianceModel model = read_compliance_file(file, &G);
    compliance_index.assign(static_cast<std::size_t>(model.vertices_m.rows()), -1);
    for (Eigen::Index i = 0; i < model.compliance_vertices.size(); ++i)
      compliance_index[static_cast<std::size_t>(model.compliance_vertices(i))] =
          static_cast<int>(i);
  }
  /// u = G f for forces on the given mesh vertices.
  Eigen::VectorXd field(const std::vector<VertexResult>& results) const {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(G.rows());
    for (const auto& r : results)
      f.segment<3>(3 * compliance_index[r.vertex]) += Eigen::Vector3d(r.force_n.data());
    return G * f;
  }
  Eigen::Vector3d at(const Eigen::VectorXd& u, std::uint32_t vertex) const {
    return u.segment<3>(3 * compliance_index[vertex]);
  }
};

double relative(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / std::max(b.norm(), std::numeric_limits<double>::min());
}

Eigen::Vector3d vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

class PalpatedTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    box_ = testing::write_box_compliance(dir_->path(), "box", 4, 85e3);
    stiff_ = testing::write_box_compliance(dir_->path(), "stiff", 4, 340e3);
    std::ofstream(dir_->path() / "palpated.toml")
        << "[daemon]\nid = \"test-daemon\"\nlog_level = \"debug\"\n"
           "[rates]\nsurface_hz = 200\nstatus_hz = 20\n"
           "[limits]\nmax_constraints = 8\n"
           "[[model]]\nid = \"box\"\nfile = \"box.h5\"\n"
           "[[model]]\nid = \"stiff\"\nfile = \"stiff.h5\"\n"
           "[[model]]\nid = \"warped\"\nfile = \"box.h5\"\nwarping = \"warped\"\n";
    daemon_ = new Daemon({"--config", (dir_->path() / "palpated.toml").string()},
                         dir_->path() / "palpated.log");
    reference_ = new Reference(box_);
  }
  static void TearDownTestSuite() {
    // A clean stop on SIGTERM exits 0.
    EXPECT_EQ(daemon_->stop(SIGTERM), 0) << daemon_->log();
    EXPECT_NE(daemon_->log().find("event=stopped"), std::string::npos) << daemon_->log();
    delete daemon_;
    delete reference_;
    delete dir_;
  }

  /// A connected client: the model is known and the reply path matched.
  static std::unique_ptr<Client> connect(const std::string& id, bool surface = false,
                                         bool status = false) {
    auto client = std::make_unique<Client>(ClientOptions{id, 0, "", surface, status});
    EXPECT_TRUE(client->wait_for_model("box", kDdsTimeout)) << daemon_->log();
    EXPECT_TRUE(client->wait_for_service(kDdsTimeout)) << daemon_->log();
    return client;
  }
  static ModelInfo box_info(Client& client) { return *client.wait_for_model("box", kDdsTimeout); }

  inline static TempDir* dir_ = nullptr;
  inline static std::filesystem::path box_, stiff_;
  inline static Daemon* daemon_ = nullptr;
  inline static Reference* reference_ = nullptr;
};

TEST_F(PalpatedTest, DescribesEachModelToLateJoiners) {
  auto client = connect("describe");
  const ModelInfo m = box_info(*client);
  const Reference& ref = *reference_;
  EXPECT_EQ(m.surface.compliance_vertex_count * 3, ref.G.rows());
  EXPECT_EQ(m.surface.rest_positions_m.size(), 3 * m.surface.vertex_ids.size());
  EXPECT_EQ(m.surface.triangles.size() % 3, 0u);
  EXPECT_GT(m.surface.triangles.size(), 0u);
  for (int i = 0; i < m.surface.compliance_vertex_count; ++i)
    EXPECT_EQ(ref.compliance_index[m.surface.vertex_ids[i]], i);
  EXPECT_EQ(m.units, "m, N (SI)");
  EXPECT_NE(m.material_summary.find("85000"), std::string::npos) << m.material_summary;
  EXPECT_EQ(m.input_hash.rfind("sha256:", 0), 0u);
  // The bounds on a request's values: 10 % of the organ's size (the box's
  // surface diagonal), 50 N (palpated's defaults).
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (std::size_t v = 0; v < m.surface.vertex_ids.size(); ++v) {
    const Eigen::Vector3d x(&m.surface.rest_positions_m[3 * v]);
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  EXPECT_NEAR(m.max_displacement_m, 0.1 * (hi - lo).norm(), 1e-15);
  EXPECT_EQ(m.max_force_n, 50.0);
  EXPECT_TRUE(client->wait_for_model("stiff", kDdsTimeout));
}

TEST_F(PalpatedTest, ANewClientsFirstRequestIsAnsweredWithoutWaitingForTheService) {
  // Issue 35: a first client program, wait_for_model then request, lost its
  // request on 3 of 6 runs (the reply writer not matched yet). request()
  // now waits for the match itself: twenty new clients in a row, each
  // asking at once, all answered.
  for (int i = 0; i < 20; ++i) {
    Client client(ClientOptions{"first-" + std::to_string(i), 0, "", false, false});
    const auto m = client.wait_for_model("box", kDdsTimeout);
    ASSERT_TRUE(m) << daemon_->log();
    const std::vector<ConstraintSpec> cs{
        ConstraintSpec::force(m->surface.vertex_ids[0], {0, 0, -0.1})};
    const Reply reply = client.request("box", cs, false, true, kDdsTimeout);
    EXPECT_EQ(reply.status, RequestStatus::kOk) << "client " << i << ": " << reply.message;
  }
}

TEST_F(PalpatedTest, ARequestWithNoPalpatedSaysNoneIsMatchedAndWhere) {
  // Domain 7 has no palpated: the message says none was matched, not that
  // a running one did not answer.
  Client client(ClientOptions{"alone", 7, "", false, false});
  try {
    client.request("box", {}, false, true, std::chrono::milliseconds(300));
    ADD_FAILURE() << "a request with no palpated returned";
  } catch (const SystemError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no palpated serves client alone on domain 7"), std::string::npos) << what;
    EXPECT_NE(what.find("within 300 ms"), std::string::npos) << what;
  }
}

TEST_F(PalpatedTest, AnswersEveryKindOfRequestLikeTheDenseComputation) {
  auto client = connect("kinds");
  const ModelInfo m = box_info(*client);
  const Reference& ref = *reference_;
  const std::uint32_t a = m.surface.vertex_ids[2], b = m.surface.vertex_ids[9],
                      c = m.surface.vertex_ids[14], d = m.surface.vertex_ids[30];

  // Forces: the surface field is G f.
  {
    const std::vector<ConstraintSpec> cs{ConstraintSpec::force(a, {0.1, 0, -0.3}),
                                         ConstraintSpec::force(b, {0, 0.2, 0})};
    const Reply reply = client->request("box", cs, true);
    ASSERT_EQ(reply.status, RequestStatus::kOk) << reply.message;
    EXPECT_EQ(reply.model_id, "box");
    ASSERT_EQ(reply.results.size(), 2u);
    EXPECT_EQ(reply.results[0].vertex, a);
    EXPECT_EQ(vec(reply.results[0].force_n), Eigen::Vector3d(0.1, 0, -0.3));
    EXPECT_LT(relative(Eigen::Map<const Eigen::VectorXd>(reply.surface_displacement_m.data(),
                                                         ref.G.rows()),
                       ref.field(reply.results)),
              kDdsTolerance);
    EXPECT_LT((vec(reply.total_force_n) - Eigen::Vector3d(0.1, 0.2, -0.3)).norm(), 1e-15);
    EXPECT_GT(reply.solve_ns, 0u);
  }
  // Imposed displacements on three vertices: F = G_CC⁻¹ U.
  {
    const std::vector<std::uint32_t> vs{a, b, c};
    const std::vector<ConstraintSpec> cs{ConstraintSpec::displacement(a, {0, 0, -0.002}),
                                         ConstraintSpec::displacement(b, {0.001, 0, -0.001}),
                                         ConstraintSpec::displacement(c, {0, 0, 0.0005})};
    const Reply reply = client->request("box", cs, true);
    ASSERT_EQ(reply.status, RequestStatus::kOk) << reply.message;
    Eigen::MatrixXd G_CC(9, 9);
    Eigen::VectorXd U(9), F(9);
    for (int i = 0; i < 3; ++i) {
      U.segment<3>(3 * i) = vec(cs[i].value);
      F.segment<3>(3 * i) = vec(reply.results[i].force_n);
      for (int j = 0; j < 3; ++j)
        G_CC.block<3, 3>(3 * i, 3 * j) =
            ref.G.block<3, 3>(3 * ref.compliance_index[vs[i]], 3 * ref.compliance_index[vs[j]]);
    }
    EXPECT_LT(relative(F, G_CC.fullPivLu().solve(U)), kDdsTolerance);
    const Eigen::VectorXd u = ref.field(reply.results);
    EXPECT_LT(
        relative(Eigen::Map<const Eigen::VectorXd>(reply.surface_displacement_m.data(), u.size()),
                 u),
        kDdsTolerance);
    EXPECT_GE(reply.condition_estimate, 1.0);
  }
  // Mixed, with sliding: each condition holds on the dense field.
  {
    const Eigen::Vector3d n = Eigen::Vector3d(0, 0.3, 1).normalized();
    const std::vector<ConstraintSpec> cs{
        ConstraintSpec::force(a, {0, 0, -0.2}), ConstraintSpec::displacement(b, {0, 0.001, 0}),
        ConstraintSpec::normal_displacement(c, {0, 0.3, 1}, -0.0015),
        ConstraintSpec::normal_displacement(d, {1, 0, 0}, 0.001)};
    const Reply reply = client->request("box", cs, false);
    ASSERT_EQ(reply.status, RequestStatus::kOk) << reply.message;
    EXPECT_TRUE(reply.surface_displacement_m.empty()) << "not asked for";
    const Eigen::VectorXd u = ref.field(reply.results);
    EXPECT_LT((vec(reply.results[0].force_n) - Eigen::Vector3d(0, 0, -0.2)).norm(), 1e-15);
    EXPECT_LT((ref.at(u, b) - Eigen::Vector3d(0, 0.001, 0)).norm(), kDdsTolerance * 0.001);
    EXPECT_NEAR(n.dot(ref.at(u, c)), -0.0015, kDdsTolerance * 0.0015);
    EXPECT_NEAR(ref.at(u, d).x(), 0.001, kDdsTolerance * 0.001);
    const Eigen::Vector3d fc = vec(reply.results[2].force_n);
    EXPECT_LT((fc - fc.dot(n) * n).norm(), 1e-12 * fc.norm()) << "sliding: no tangential force";
    for (std::size_t j = 0; j < cs.size(); ++j)
      EXPECT_LT((vec(reply.results[j].displacement_m) - ref.at(u, cs[j].vertex)).norm(),
                kDdsTolerance * u.norm());
  }
}

// A model served with warping = "warped" says so in its description and
// answers requests as the library's WarpedSolver does in process (the same
// code on the same file: to round-off), which differs from the linear
// answer for a lift of the free end (docs/model/warped.md, "Large rotations").
TEST_F(PalpatedTest, AWarpedModelSaysSoAndAnswersAsTheWarpedSolver) {
  auto client = connect("warped");
  EXPECT_EQ(box_info(*client).mechanics, "linear");
  const auto described = client->wait_for_model("warped", kDdsTimeout);
  ASSERT_TRUE(described.has_value());
  EXPECT_EQ(described->mechanics, "warped");

  const SurfaceModel model = load_surface_model("warped", box_);
  const RotationField field(model.surface, default_smoothing_radius(model.surface));
  SolverLimits limits;
  limits.max_constraints = 8;
  WarpedSolver solver(model, limits, field);
  // The free end's top edge (x = 100 mm, z = 40 mm) lifted 10 mm and pulled 3 mm.
  std::vector<ConstraintSpec> cs;
  for (int v = 0; v < model.compliance_vertex_count() && cs.size() < 4; ++v) {
    const Eigen::Vector3d p = model.surface.rest_position(v);
    if (p.x() > 0.1 - 1e-9 && p.z() > 0.04 - 1e-9)
      cs.push_back(ConstraintSpec::displacement(model.surface.vertex_ids[std::size_t(v)],
                                                {-0.003, 0, 0.010}));
  }
  ASSERT_GE(cs.size(), 2u);
  ASSERT_EQ(solver.begin(cs.size()), RequestStatus::kOk);
  for (const auto& c : cs)
    ASSERT_EQ(solver.add(c.vertex, 1, c.value.data(), c.normal.data()), RequestStatus::kOk);
  ASSERT_EQ(solver.solve(), RequestStatus::kOk) << solver.message();
  Eigen::VectorXd field_m(model.compliance_rows());
  solver.surface_displacement(field_m);

  const Reply warped = client->request("warped", cs, true);
  ASSERT_EQ(warped.status, RequestStatus::kOk) << warped.message;
  const Reply linear = client->request("box", cs, false);
  ASSERT_EQ(linear.status, RequestStatus::kOk) << linear.message;
  for (std::size_t j = 0; j < cs.size(); ++j) {
    const Eigen::Vector3d f(&solver.forces()[3 * j]);
    EXPECT_LT((vec(warped.results[j].force_n) - f).norm(), 1e-12 * f.norm()) << j;
    EXPECT_LT((vec(warped.results[j].displacement_m) - vec(cs[j].value)).norm(), 1e-9) << j;
  }
  EXPECT_LT(relative(Eigen::Map<const Eigen::VectorXd>(warped.surface_displacement_m.data(),
                                                       field_m.size()),
                     field_m),
            1e-12);
  EXPECT_GT((vec(warped.total_force_n) - vec(linear.total_force_n)).norm(),
            0.01 * vec(linear.total_force_n).norm());
}

TEST_F(PalpatedTest, ServesEachModelWithItsOwnCompliance) {
  // Same mesh, E four times larger: G is four times smaller, the force for the
  // same imposed displacement four times larger.
  auto client = connect("models");
  const ModelInfo m = box_info(*client);
  const std::vector<ConstraintSpec> cs{
      ConstraintSpec::displacement(m.surface.vertex_ids[5], {0, 0, -0.001})};
  const Reply soft = client->request("box", cs);
  const Reply stiff = client->request("stiff", cs);
  ASSERT_EQ(soft.status, RequestStatus::kOk);
  ASSERT_EQ(stiff.status, RequestStatus::kOk);
  EXPECT_LT(relative(vec(stiff.total_force_n), 4.0 * vec(soft.total_force_n)), 1e-9);
}

TEST_F(PalpatedTest, SeveralClientsAtOnceGetOnlyTheirOwnReplies) {
  constexpr int kClients = 3, kRequests = 60;
  std::vector<std::unique_ptr<Client>> clients;
  for (int c = 0; c < kClients; ++c) clients.push_back(connect("concurrent-" + std::to_string(c)));
  const ModelInfo m = box_info(*clients[0]);
  const std::uint32_t vertex = m.surface.vertex_ids[7];
  // A single imposed displacement has force (G^kk)⁻¹ u: linear in u, so each
  // client's depth is recognisable in the force it gets back.
  const Reply unit =
      clients[0]->request("box", std::vector{ConstraintSpec::displacement(vertex, {0, 0, -0.001})});
  ASSERT_EQ(unit.status, RequestStatus::kOk);
  std::vector<int> wrong(kClients, 0);
  std::vector<std::thread> threads;
  for (int c = 0; c < kClients; ++c)
    threads.emplace_back([&, c] {
      for (int r = 0; r < kRequests; ++r) {
        const double scale = 1.0 + c + 0.01 * r;
        const auto reply = clients[static_cast<std::size_t>(c)]->request(
            "box", std::vector{ConstraintSpec::displacement(vertex, {0, 0, -0.001 * scale})});
        if (reply.status != RequestStatus::kOk ||
            relative(vec(reply.total_force_n), scale * vec(unit.total_force_n)) > kDdsTolerance)
          ++wrong[static_cast<std::size_t>(c)];
      }
    });
  for (auto& t : threads) t.join();
  for (int c = 0; c < kClients; ++c) {
    EXPECT_EQ(wrong[static_cast<std::size_t>(c)], 0) << "client " << c;
    EXPECT_EQ(clients[static_cast<std::size_t>(c)]->foreign_replies(), 0u) << "client " << c;
  }
}

TEST_F(PalpatedTest, LateViewerGetsTheShownStateAndOnlyStateChangingRequestsMoveIt) {
  auto toucher = connect("toucher");
  const ModelInfo m = box_info(*toucher);
  const Reference& ref = *reference_;
  const std::vector<ConstraintSpec> press{
      ConstraintSpec::displacement(m.surface.vertex_ids[11], {0, 0, -0.003})};
  const Reply shown = toucher->request("box", press, false, true);
  ASSERT_EQ(shown.status, RequestStatus::kOk);

  // A viewer that starts afterwards gets the description and the current state.
  Client viewer(ClientOptions{"viewer", 0, "", true, false});
  ASSERT_TRUE(viewer.wait_for_model("box", kDdsTimeout));
  const auto sample = viewer.wait_surface("box", 0, shown.request_id, kDdsTimeout);
  ASSERT_TRUE(sample) << daemon_->log();
  EXPECT_EQ(sample->source_client_id, "toucher");
  EXPECT_LT(relative(Eigen::Map<const Eigen::VectorXd>(sample->displacement_m.data(), ref.G.rows()),
                     ref.field(shown.results)),
            kDdsTolerance);
  EXPECT_LT((vec(sample->total_force_n) - vec(shown.total_force_n)).norm(), 1e-15);
  // The constraint that made the state comes with it, for drawing.
  ASSERT_EQ(sample->constrained_vertices, std::vector<std::uint32_t>{m.surface.vertex_ids[11]});
  ASSERT_EQ(sample->constrained_forces_n.size(), 3u);
  EXPECT_LT((Eigen::Map<const Eigen::Vector3d>(sample->constrained_forces_n.data()) -
             vec(shown.results[0].force_n))
                .norm(),
            1e-15);
  // A request constrains vertices: no contact points (docs/dds.md).
  EXPECT_TRUE(sample->contact_points.empty());

  // A query (update_state = false) and a refused request leave the state alone:
  // the next state the viewer sees is the next state-changing request's.
  const Reply query = toucher->request(
      "box", std::vector{ConstraintSpec::force(m.surface.vertex_ids[3], {0, 0, 1})}, false, false);
  ASSERT_EQ(query.status, RequestStatus::kOk);
  const Reply refused =
      toucher->request("box", std::vector{ConstraintSpec::force(1u << 30, {0, 0, 1})});
  ASSERT_EQ(refused.status, RequestStatus::kVertexOutOfRange);
  const Reply next = toucher->request(
      "box", std::vector{ConstraintSpec::force(m.surface.vertex_ids[4], {0, 0, -0.5})});
  ASSERT_EQ(next.status, RequestStatus::kOk);
  const auto after = viewer.wait_surface("box", sample->sequence_number + 1, 0, kDdsTimeout);
  ASSERT_TRUE(after);
  EXPECT_EQ(after->source_request_id, next.request_id) << "only state-changing successes are shown";
  EXPECT_EQ(after->sequence_number, sample->sequence_number + 1);
}

TEST_F(PalpatedTest, EveryBadRequestGetsItsErrorAndTheDaemonKeepsServing) {
  auto client = connect("bad-requests", false, true);
  const ModelInfo m = box_info(*client);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::uint32_t v = m.surface.vertex_ids[1];
  const std::uint32_t fixed = m.surface.vertex_ids.back();  // drawn after the compliance vertices
  std::uint32_t interior = 0;
  while (std::find(m.surface.vertex_ids.begin(), m.surface.vertex_ids.end(), interior) !=
         m.surface.vertex_ids.end())
    ++interior;
  struct Case {
    std::string model;
    std::vector<ConstraintSpec> constraints;
    RequestStatus status;
    std::string fragment;
  };
  const auto push = ConstraintSpec::displacement(v, {0, 0, -0.001});
  const std::vector<Case> cases{
      {"spleen", {push}, RequestStatus::kUnknownModel, "served: box, stiff"},
      {"box",
       {ConstraintSpec::force(100000, {0, 0, 1})},
       RequestStatus::kVertexOutOfRange,
       "vertex 100000"},
      {"box",
       {ConstraintSpec::force(interior, {0, 0, 1})},
       RequestStatus::kVertexNotOnSurface,
       "inside the organ"},
      {"box", {ConstraintSpec::force(fixed, {0, 0, 1})}, RequestStatus::kVertexFixed, "is fixed"},
      {"box", {push, push}, RequestStatus::kDuplicateVertex, "appears twice"},
      {"box",
       {ConstraintSpec::displacement(v, {nan, 0, 0})},
       RequestStatus::kNonFiniteValue,
       "value[0]"},
      {"box",
       {ConstraintSpec::normal_displacement(v, {0, 0, 0}, -0.001)},
       RequestStatus::kBadConstraint,
       "no direction"},
      {"box", std::vector<ConstraintSpec>(9, push), RequestStatus::kTooManyConstraints,
       "at most 8"},
      // Millimetres typed as metres, a force no tool could give, and a value
      // that would overflow the solution.
      {"box",
       {ConstraintSpec::displacement(v, {0, 0, -3})},
       RequestStatus::kDisplacementTooLarge,
       "a displacement of 3 m is larger than model 'box' accepts"},
      {"box",
       {ConstraintSpec::displacement(v, {1e308, 0, 0})},
       RequestStatus::kDisplacementTooLarge,
       "1e+308 m"},
      {"box", {ConstraintSpec::force(v, {0, 0, 500})}, RequestStatus::kForceTooLarge, "500 N"},
  };
  for (const auto& c : cases) {
    const Reply reply = client->request(c.model, c.constraints);
    EXPECT_EQ(reply.status, c.status) << c.fragment << ": " << reply.message;
    EXPECT_NE(reply.message.find(c.fragment), std::string::npos) << reply.message;
    EXPECT_TRUE(reply.results.empty());
    // docs/dds.md: every error reply but ill_conditioned carries 1.
    EXPECT_EQ(reply.condition_estimate, 1.0) << c.fragment;
    const Reply good = client->request("box", std::vector{push});
    EXPECT_EQ(good.status, RequestStatus::kOk) << "still serving after " << c.fragment;
  }
  // A field the kind does not use is ignored (docs/dds.md): a NaN normal on a force.
  ConstraintSpec force = ConstraintSpec::force(v, {0, 0, -1});
  force.normal = {nan, nan, nan};
  EXPECT_EQ(client->request("box", std::vector{force}).status, RequestStatus::kOk);
  // The heartbeat counts the refusals.
  std::optional<StatusSample> status;
  for (int i = 0; i < 50 && (!status || status->error_replies < cases.size()); ++i)
    status = client->wait_status(kDdsTimeout);
  ASSERT_TRUE(status);
  EXPECT_GE(status->error_replies, cases.size());
  EXPECT_GE(status->requests_served, 2 * cases.size());
  EXPECT_EQ(status->daemon_id, "test-daemon");
  EXPECT_EQ(status->models, 3u);  // box, stiff and warped
}

TEST_F(PalpatedTest, RefusesIllConditionedSystemsWithTheEstimate) {
  // A second daemon on another domain with a condition limit of 1.5, which
  // any two-vertex displacement system exceeds; SIGINT stops it cleanly.
  Daemon strict({"--model", "box=" + box_.string(), "--domain", "3", "--max-condition", "1.5"},
                dir_->path() / "strict.log");
  Client client(ClientOptions{"conditioning", 3, "", false, false});
  const auto m = client.wait_for_model("box", kDdsTimeout);
  ASSERT_TRUE(m) << strict.log();
  ASSERT_TRUE(client.wait_for_service(kDdsTimeout));
  const std::vector<ConstraintSpec> cs{
      ConstraintSpec::displacement(m->surface.vertex_ids[0], {0, 0, 0.001}),
      ConstraintSpec::displacement(m->surface.vertex_ids[1], {0, 0, 0.001})};
  const Reply reply = client.request("box", cs);
  EXPECT_EQ(reply.status, RequestStatus::kIllConditioned);
  EXPECT_GT(reply.condition_estimate, 1.5);
  EXPECT_NE(reply.message.find("condition estimate"), std::string::npos) << reply.message;
  EXPECT_EQ(strict.stop(SIGINT), 0) << strict.log();
}

TEST(PalpatedStartUp, StopsWithAClearMessageOnBadFilesAndConfiguration) {
  TempDir dir;
  auto run = [&](const std::vector<std::string>& args) {
    Daemon daemon(args, dir / "out.log");
    const int code = daemon.stop(0);
    return std::make_pair(code, daemon.log());
  };
  {
    const auto [code, log] = run({"--model", "liver=" + (dir / "missing.h5").string()});
    EXPECT_EQ(code, 2) << log;
    EXPECT_NE(log.find("missing.h5 does not exist"), std::string::npos) << log;
  }
  {
    std::ofstream(dir / "not-hdf5.h5") << "this is not an HDF5 file\n";
    const auto [code, log] = run({"--model", "liver=" + (dir / "not-hdf5.h5").string()});
    EXPECT_EQ(code, 2) << log;
    EXPECT_NE(log.find("not-hdf5.h5"), std::string::npos) << log;
    // One line says what is wrong, with the file.
    const auto line = log.find("palpated: error: ");
    ASSERT_NE(line, std::string::npos) << log;
    EXPECT_NE(log.substr(line, log.find('\n', line) - line).find("not-hdf5.h5"), std::string::npos)
        << log;
  }
  {
    std::ofstream(dir / "bad.toml") << "[rates]\nsurface_hz = 0\n";
    const auto [code, log] = run({"--config", (dir / "bad.toml").string()});
    EXPECT_EQ(code, 2) << log;
    EXPECT_NE(log.find("bad.toml:2: rates.surface_hz"), std::string::npos) << log;
  }
  {
    const auto box = testing::write_box_compliance(dir.path());
    const auto [code, log] = run({"--model", "box=" + box.string(), "--check-config"});
    EXPECT_EQ(code, 0) << log;
    EXPECT_EQ(log.find("warning"), std::string::npos) << log;
  }
  {
    // The box in millimetres read as metres: 100 m long. Served, with a
    // warning where precompute gave one (issue 35), in --check-config and
    // in the log of a served model.
    const auto huge = testing::write_clamped_compliance(testing::box_mesh(100, 50, 40, 4, 2, 2),
                                                        dir.path(), "huge", 85e3);
    const auto [code, log] = run({"--model", "huge=" + huge.string(), "--check-config"});
    EXPECT_EQ(code, 0) << log;
    EXPECT_NE(log.find("palpated: warning: model huge: the organ is 119 m across, not an "
                       "organ's size (0.01 to 1 m)"),
              std::string::npos)
        << log;
    Daemon served({"--model", "huge=" + huge.string(), "--domain", "5"}, dir / "huge.log");
    Client client(ClientOptions{"huge-check", 5, "", false, false});
    EXPECT_TRUE(client.wait_for_model("huge", kDdsTimeout)) << served.log();
    EXPECT_EQ(served.stop(SIGTERM), 0) << served.log();
    EXPECT_NE(served.log().find("event=organ_size_suspicious model=huge across_m=119"),
              std::string::npos)
        << served.log();
  }
}

}  // namespace
}  // namespace palpate
