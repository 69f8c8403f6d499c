// The DDS side of palpate-viewer: palpated's topics in, browser messages out
// (docs/viewer.md describes both ends of the wire format written here).

#include "feed.hpp"

#include <dds/dds.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>
#include <unordered_map>

#include "palpate.h"
#include "palpate/core/error.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate::viewer {
namespace {

static_assert(std::endian::native == std::endian::little,
              "the binary frames are little-endian, as browsers' typed arrays are");

using Clock = std::chrono::steady_clock;
using nlohmann::json;

/// Appends little-endian 32-bit words to a binary frame; every field starts
/// on a 4-byte boundary so the page can view arrays in place.
class FrameWriter {
 public:
  explicit FrameWriter(std::uint32_t kind) { u32(kind); }
  void u32(std::uint32_t v) { append(&v, 4); }
  void f32(double v) {
    const auto f = static_cast<float>(v);
    append(&f, 4);
  }
  void string(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size()));
    bytes_.append(s);
    bytes_.append((4 - s.size() % 4) % 4, '\0');
  }
  void reserve(std::size_t n) { bytes_.reserve(n); }
  std::string take() { return std::move(bytes_); }

 private:
  void append(const void* p, std::size_t n) { bytes_.append(static_cast<const char*>(p), n); }
  std::string bytes_;
};

constexpr std::uint32_t kGeometryFrame = 1;
constexpr std::uint32_t kSurfaceFrame = 2;
constexpr std::uint32_t kNoVertex = 0xffffffffu;

json latency_json(const LatencySummary& l) {
  return {{"p50_us", l.p50_us}, {"p99_us", l.p99_us}, {"p999_us", l.p999_us}, {"max_us", l.max_us}};
}

template <std::size_t N>
json array_json(const double (&v)[N]) {
  return json(std::vector<double>(v, v + N));
}

/// What the feed knows of one tool between two tool messages.
struct ToolView {
  std::string model_id;
  double position[3] = {};
  double orientation[4] = {1, 0, 0, 0};
  double jaw_angle = 0;
  double force[3] = {};
  double grip_force = 0;
  std::uint32_t contacts = 0;
  ToolState state = ToolState::kFree;
  bool force_limited = false, watchdog = false;
  std::uint64_t poses = 0, feedbacks = 0;
  double compute_us = 0;
  Clock::time_point last_heard;  // last pose or feedback
};

// A tool silent for this long leaves the page (its client stopped).
constexpr auto kToolForgotten = std::chrono::seconds(2);
// Tools drawn at most: ids beyond are ignored (a misbehaving client cannot
// grow the bridge without bound).
constexpr std::size_t kMaxTools = 64;
// Contact points passed on per surface frame at most (palpated sends at most
// limits.max_constraints, 64 by default, 1024 at most).
constexpr std::size_t kMaxContactPoints = 1024;

}  // namespace

struct Feed::Impl {
  FeedOptions options;
  Sink sink;
  dds::Participant participant;
  dds::Entity waitset;
  dds_entity_t stop_condition = 0;
  enum Reader { kModels, kSurfaces, kStatus, kPoses, kFeedback, kEvents, kReaderCount };
  dds_entity_t readers[kReaderCount] = {};
  std::atomic<bool> stopping{false};
  std::thread thread;

  // Owned by the thread.
  std::unordered_map<std::string, std::unordered_map<std::uint32_t, std::uint32_t>> drawn_index;
  std::map<std::string, ToolView> tools;
  bool tools_changed = false;
  json daemon_status;  // null until the first status
  std::uint64_t surfaces = 0, poses = 0, feedbacks = 0;

  Impl(const FeedOptions& o, Sink s) : options(o), sink(std::move(s)) {
    participant = dds::join_domain(options.domain_id, options.dds_config);
    const dds_entity_t p = participant.get();
    struct Spec {
      const dds_topic_descriptor_t* type;
      const char* name;
      dds::Qos qos;
    };
    Spec specs[kReaderCount] = {
        {&palpate_ModelDescription_desc, dds::kModelTopic, dds::model_qos()},
        {&palpate_SurfaceDisplacement_desc, dds::kSurfaceTopic, dds::surface_qos()},
        {&palpate_DaemonStatus_desc, dds::kStatusTopic, dds::status_qos()},
        {&palpate_ToolPose_desc, dds::kToolPoseTopic, dds::tool_stream_qos()},
        {&palpate_ToolFeedback_desc, dds::kToolFeedbackTopic, dds::tool_stream_qos()},
        {&palpate_ToolEvent_desc, dds::kToolEventTopic, dds::tool_event_qos()},
    };
    waitset = dds::Entity(dds::check(dds_create_waitset(p), "creating the viewer's waitset"));
    for (int r = 0; r < kReaderCount; ++r) {
      const std::string what = std::string("creating the reader of ") + specs[r].name;
      readers[r] = dds::check(dds_create_reader(p, dds::topic(p, specs[r].type, specs[r].name),
                                                specs[r].qos.get(), nullptr),
                              what);
      const dds_entity_t condition =
          dds::check(dds_create_readcondition(readers[r], DDS_ANY_STATE), what);
      dds::check(dds_waitset_attach(waitset.get(), condition, r), what);
    }
    stop_condition =
        dds::check(dds_create_guardcondition(p), "creating the viewer's stop condition");
    dds::check(dds_waitset_attach(waitset.get(), stop_condition, kReaderCount),
               "attaching the stop condition");
    thread = std::thread([this] { run(); });
  }

  ~Impl() {
    stopping.store(true);
    dds_set_guardcondition(stop_condition, true);
    if (thread.joinable()) thread.join();
  }

  /// Takes every sample of reader @p r and hands the valid ones to @p use,
  /// and the instances that are no longer alive (their writer disposed them
  /// or is gone: palpated stopped) to @p gone, as a sample whose key fields
  /// alone are set.
  template <typename Sample, typename Use, typename Gone>
  void take_all(Reader r, Use use, Gone gone) {
    constexpr int kBatch = 16;
    void* samples[kBatch] = {};
    dds_sample_info_t infos[kBatch];
    for (;;) {
      const dds_return_t n = dds_take(readers[r], samples, infos, kBatch, kBatch);
      if (n <= 0) return;
      for (int i = 0; i < n; ++i) {
        const auto& sample = *static_cast<const Sample*>(samples[i]);
        if (infos[i].valid_data)
          use(sample);
        else if (infos[i].instance_state != DDS_IST_ALIVE)
          gone(sample);
      }
      dds_return_loan(readers[r], samples, n);
      if (n < kBatch) return;
    }
  }
  template <typename Sample, typename Use>
  void take_all(Reader r, Use use) {
    take_all<Sample>(r, use, [](const Sample&) {});
  }

  void run() {
    const auto tools_period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / options.tools_rate_hz));
    const auto status_period = std::chrono::seconds(1);
    auto next_tools = Clock::now() + tools_period;
    auto next_status = Clock::now() + status_period;
    auto last_status = Clock::now();
    while (!stopping.load()) {
      const auto wake = std::min(next_tools, next_status);
      const auto timeout = std::max<std::int64_t>(
          0, std::chrono::duration_cast<std::chrono::nanoseconds>(wake - Clock::now()).count());
      dds_attach_t triggered[kReaderCount + 1];
      dds_waitset_wait(waitset.get(), triggered, kReaderCount + 1, timeout);
      if (stopping.load()) break;
      take_all<palpate_ModelDescription>(kModels, [&](const auto& d) { on_model(d); });
      take_all<palpate_SurfaceDisplacement>(
          kSurfaces, [&](const auto& s) { on_surface(s); },
          [&](const auto& s) { on_surface_ended(s); });
      take_all<palpate_DaemonStatus>(kStatus, [&](const auto& s) { on_status(s); });
      take_all<palpate_ToolPose>(kPoses, [&](const auto& p) { on_pose(p); });
      take_all<palpate_ToolFeedback>(kFeedback, [&](const auto& f) { on_feedback(f); });
      take_all<palpate_ToolEvent>(kEvents, [&](const auto& e) { on_event(e); });
      const auto now = Clock::now();
      if (now >= next_tools) {
        forget_silent_tools(now);
        if (tools_changed) send_tools();
        next_tools = std::max(next_tools + tools_period, now);
      }
      if (now >= next_status) {
        send_status(std::chrono::duration<double>(now - last_status).count());
        last_status = now;
        next_status = std::max(next_status + status_period, now);
      }
    }
  }

  void on_model(const palpate_ModelDescription& description) {
    const ModelInfo m = wire::from_idl(description);
    const DrawnSurface& surface = m.surface;
    const auto nv = static_cast<std::uint32_t>(surface.vertex_count());
    const auto nt = static_cast<std::uint32_t>(surface.triangle_count());
    const auto compliance = static_cast<std::uint32_t>(surface.compliance_vertex_count);
    if (surface.rest_positions_m.size() != 3 * std::size_t{nv} || compliance > nv) {
      // A daemon of another version: say so once per description, draw nothing.
      sink(
          {Message::Kind::kEvent,
           m.model_id,
           json{{"type", "warning"},
                {"message", "model " + m.model_id + ": inconsistent description (" +
                                std::to_string(surface.rest_positions_m.size()) +
                                " coordinates for " + std::to_string(nv) + " vertices); not drawn"}}
               .dump(),
           {}});
      return;
    }
    auto& index = drawn_index[m.model_id];
    index.clear();
    for (std::uint32_t v = 0; v < nv; ++v) index.emplace(surface.vertex_ids[v], v);

    json text = {{"type", "model"},
                 {"model_id", m.model_id},
                 {"units", m.units},
                 {"material", m.material_summary},
                 {"mechanics", m.mechanics},
                 {"cut_region", m.cut_region},
                 {"input_hash", m.input_hash},
                 {"vertex_count", nv},
                 {"compliance_vertex_count", compliance},
                 {"triangle_count", nt}};
    FrameWriter frame(kGeometryFrame);
    frame.reserve(64 + 12 * static_cast<std::size_t>(nv) + 12 * static_cast<std::size_t>(nt));
    frame.string(m.model_id);
    frame.u32(nv);
    frame.u32(compliance);
    frame.u32(nt);
    for (const double x : surface.rest_positions_m) frame.f32(x);
    for (std::uint32_t i = 0; i < 3 * nt; ++i) {
      const std::uint32_t v = surface.triangles[i];
      frame.u32(v < nv ? v : 0);
    }
    sink({Message::Kind::kModel, m.model_id, text.dump(), frame.take()});
  }

  void on_surface(const palpate_SurfaceDisplacement& sample) {
    ++surfaces;
    const SurfaceSample s = wire::from_idl(sample);
    const auto index = drawn_index.find(s.model_id);
    const auto ns = static_cast<std::uint32_t>(s.displacement_m.size() / 3);
    const auto nc = static_cast<std::uint32_t>(
        std::min(s.constrained_vertices.size(), s.constrained_forces_n.size() / 3));
    FrameWriter frame(kSurfaceFrame);
    frame.reserve(128 + 12 * static_cast<std::size_t>(ns) + 16 * static_cast<std::size_t>(nc) +
                  64 * s.contact_points.size() + 4 * s.region_positions_m.size() +
                  4 * s.region_triangles.size() + 4 * s.hidden_triangles.size());
    frame.string(s.model_id);
    frame.string(s.source_client_id);
    frame.u32(static_cast<std::uint32_t>(s.sequence_number));
    frame.u32(static_cast<std::uint32_t>(s.sequence_number >> 32));
    frame.u32(ns);
    frame.u32(nc);
    for (const double f : s.total_force_n) frame.f32(f);
    for (std::uint32_t i = 0; i < 3 * ns; ++i) frame.f32(s.displacement_m[i]);
    for (std::uint32_t c = 0; c < nc; ++c) {
      std::uint32_t drawn = kNoVertex;
      if (index != drawn_index.end())
        if (const auto it = index->second.find(s.constrained_vertices[c]);
            it != index->second.end())
          drawn = it->second;
      frame.u32(drawn);
    }
    for (std::uint32_t i = 0; i < 3 * nc; ++i) frame.f32(s.constrained_forces_n[i]);
    write_contact_points(s, index == drawn_index.end() ? nullptr : &index->second, frame);
    write_region(s, frame);
    sink({Message::Kind::kSurface, s.model_id, {}, frame.take()});
  }

  /// The served cut region, after the contact points (a page that predates
  /// it stops reading before): its topology version, its deformed vertices,
  /// its visible triangles and the model's triangles it covers
  /// (docs/viewer.md, "Surface frame"). A triangle naming a vertex the
  /// region does not have is sent as (0, 0, 0): degenerate, not drawn.
  static void write_region(const SurfaceSample& s, FrameWriter& frame) {
    const auto nrv = static_cast<std::uint32_t>(s.region_positions_m.size() / 3);
    const auto nrt = static_cast<std::uint32_t>(s.region_triangles.size() / 3);
    const auto nh = static_cast<std::uint32_t>(s.hidden_triangles.size());
    frame.u32(static_cast<std::uint32_t>(s.topology_version));
    frame.u32(static_cast<std::uint32_t>(s.topology_version >> 32));
    frame.u32(nrv);
    frame.u32(nrt);
    frame.u32(nh);
    for (std::uint32_t i = 0; i < 3 * nrv; ++i) frame.f32(s.region_positions_m[i]);
    for (std::uint32_t t = 0; t < nrt; ++t) {
      const std::uint32_t* corners = &s.region_triangles[3 * std::size_t{t}];
      const bool valid = corners[0] < nrv && corners[1] < nrv && corners[2] < nrv;
      for (int c = 0; c < 3; ++c) frame.u32(valid ? corners[c] : 0);
    }
    for (const std::uint32_t h : s.hidden_triangles) frame.u32(h);
  }

  /// The tools' contact points, after the constrained vertices (a page that
  /// predates them stops reading before): the tools' ids, then per point
  /// its tool (index into those ids), whether it is held, its drawn vertices
  /// (kNoVertex when unused or unknown), weights, position and force
  /// (docs/viewer.md, "Surface frame").
  static void write_contact_points(const SurfaceSample& s,
                                   const std::unordered_map<std::uint32_t, std::uint32_t>* index,
                                   FrameWriter& frame) {
    const auto& points = s.contact_points;
    const auto np = static_cast<std::uint32_t>(std::min(points.size(), kMaxContactPoints));
    std::vector<std::string> ids;
    std::vector<std::uint32_t> tool_of(np);
    for (std::uint32_t c = 0; c < np; ++c) {
      const auto it = std::find(ids.begin(), ids.end(), points[c].tool_id);
      tool_of[c] = static_cast<std::uint32_t>(it - ids.begin());
      if (it == ids.end()) ids.push_back(points[c].tool_id);
    }
    frame.u32(static_cast<std::uint32_t>(ids.size()));
    for (const std::string& id : ids) frame.string(id);
    frame.u32(np);
    for (std::uint32_t c = 0; c < np; ++c) frame.u32(tool_of[c]);
    for (std::uint32_t c = 0; c < np; ++c) frame.u32(points[c].held ? 1 : 0);
    for (std::uint32_t c = 0; c < np; ++c)
      for (const std::uint32_t v : points[c].vertices) {
        std::uint32_t drawn = kNoVertex;
        if (index)
          if (const auto it = index->find(v); it != index->end()) drawn = it->second;
        frame.u32(drawn);
      }
    for (std::uint32_t c = 0; c < np; ++c)
      for (const double w : points[c].weights) frame.f32(w);
    for (std::uint32_t c = 0; c < np; ++c)
      for (const double x : points[c].position_m) frame.f32(x);
    for (std::uint32_t c = 0; c < np; ++c)
      for (const double f : points[c].force_n) frame.f32(f);
  }

  /// A model's surface stream has no live writer any more (palpated
  /// stopped, or was lost): its last sample is no longer the model's state,
  /// and a page that joins later must not draw it.
  void on_surface_ended(const palpate_SurfaceDisplacement& key_only) {
    const std::string model_id(wire::bounded(key_only.model_id));
    sink({Message::Kind::kSurfaceEnded,
          model_id,
          json{{"type", "surface_ended"}, {"model_id", model_id}}.dump(),
          {}});
  }

  void on_status(const palpate_DaemonStatus& status) {
    const StatusSample s = wire::from_idl(status);
    daemon_status = {{"daemon_id", s.daemon_id},
                     {"uptime_s", static_cast<double>(s.uptime_ns) * 1e-9},
                     {"models", s.models},
                     {"clients", s.clients},
                     {"requests_served", s.requests_served},
                     {"request_rate_hz", s.request_rate_hz},
                     {"surface_rate_hz", s.surface_rate_hz},
                     {"tool_poses", s.tool_poses},
                     {"tool_poses_refused", s.tool_poses_refused},
                     {"solve", latency_json(s.solve)},
                     {"tool_compute", latency_json(s.tool_compute)}};
  }

  /// The view of tool @p id, made on first sight; nullptr beyond kMaxTools.
  ToolView* tool(std::string_view id) {
    auto it = tools.find(std::string(id));
    if (it == tools.end()) {
      if (tools.size() >= kMaxTools) return nullptr;
      it = tools.emplace(std::string(id), ToolView{}).first;
    }
    it->second.last_heard = Clock::now();
    return &it->second;
  }

  void forget_silent_tools(Clock::time_point now) {
    tools_changed |= std::erase_if(tools, [&](const auto& entry) {
                       return now - entry.second.last_heard > kToolForgotten;
                     }) > 0;
  }

  void on_pose(const palpate_ToolPose& p) {
    ++poses;
    ToolView* view = tool(wire::bounded(p.tool_id));
    if (!view) return;
    ToolView& t = *view;
    const ToolPoseInput pose = wire::from_idl(p);
    t.model_id = wire::bounded(p.model_id);
    for (int d = 0; d < 3; ++d) t.position[d] = pose.position_m[d];
    t.orientation[0] = pose.orientation.w();
    t.orientation[1] = pose.orientation.x();
    t.orientation[2] = pose.orientation.y();
    t.orientation[3] = pose.orientation.z();
    t.jaw_angle = pose.jaw_angle_rad;
    ++t.poses;
    tools_changed = true;
  }

  void on_feedback(const palpate_ToolFeedback& f) {
    ++feedbacks;
    ToolView* view = tool(wire::bounded(f.tool_id));
    if (!view) return;
    ToolView& t = *view;
    const ToolFeedbackSample sample = wire::from_idl(f, 0);
    std::copy_n(sample.force_n.begin(), 3, t.force);
    t.grip_force = sample.grip_n;
    t.contacts = sample.contacts;
    t.state = sample.state;
    t.force_limited = sample.force_limited;
    t.watchdog = sample.watchdog;
    t.compute_us = static_cast<double>(sample.compute_ns) * 1e-3;
    ++t.feedbacks;
    tools_changed = true;
  }

  void on_event(const palpate_ToolEvent& e) {
    const ToolEventSample event = wire::from_idl(e, 0);
    sink({Message::Kind::kEvent,
          event.tool_id,
          json{{"type", "event"},
               {"tool_id", event.tool_id},
               {"model_id", event.model_id},
               {"kind", tool_event_name(event.kind)},
               {"held_vertices", event.held_vertices},
               {"pose_sequence", event.pose_sequence}}
              .dump(),
          {}});
  }

  const ToolGeometry& geometry(const std::string& id) const {
    static const ToolGeometry defaults;
    for (const auto& g : options.tools)
      if (g.id == id) return g;
    return defaults;
  }

  void send_tools() {
    tools_changed = false;
    json list = json::array();
    for (const auto& [id, t] : tools) {
      const ToolGeometry& g = geometry(id);
      list.push_back({{"tool_id", id},
                      {"model_id", t.model_id},
                      {"position", array_json(t.position)},
                      {"orientation", array_json(t.orientation)},
                      {"jaw_angle", t.jaw_angle},
                      {"force", array_json(t.force)},
                      {"grip_force", t.grip_force},
                      {"contacts", t.contacts},
                      {"state", tool_state_name(t.state)},
                      {"force_limited", t.force_limited},
                      {"watchdog", t.watchdog},
                      {"compute_us", t.compute_us},
                      {"poses", t.poses},
                      {"geometry",
                       {{"tip", g.tip == TipShape::kSphere ? "sphere" : "capsule"},
                        {"tip_radius", g.tip_radius_m},
                        {"tip_length", g.tip_length_m},
                        {"jaw_length", g.jaw_length_m},
                        {"jaw_width", g.jaw_width_m},
                        {"force_limit", g.force_limit_n}}}});
    }
    sink({Message::Kind::kTools, "tools", json{{"type", "tools"}, {"tools", list}}.dump(), {}});
  }

  void send_status(double interval_s) {
    const json bridge = {{"surface_hz", static_cast<double>(surfaces) / interval_s},
                         {"pose_hz", static_cast<double>(poses) / interval_s},
                         {"feedback_hz", static_cast<double>(feedbacks) / interval_s}};
    surfaces = poses = feedbacks = 0;
    sink({Message::Kind::kStatus,
          "status",
          json{{"type", "status"}, {"daemon", daemon_status}, {"bridge", bridge}}.dump(),
          {}});
  }
};

Feed::Feed(const FeedOptions& options, Sink sink)
    : impl_(std::make_unique<Impl>(options, std::move(sink))) {}
Feed::~Feed() = default;
const std::string& Feed::dds_origin() const { return impl_->participant.config.origin; }

}  // namespace palpate::viewer
