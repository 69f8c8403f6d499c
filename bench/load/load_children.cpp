// palpate_load_generator's children: the stations (haptic tools at 1 kHz),
// the viewers (the surface stream and the heartbeat) and the requester
// (reliable requests), each a process of its own with its own DDS
// participant (load_generator.cpp forks them before any DDS exists).

#include <fmt/format.h>

#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <thread>

#include "load_common.hpp"
#include "palpate.h"
#include "palpate/runtime/gesture.hpp"
#include "palpate/transport/client.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/tool_client.hpp"

namespace palpate::load {

using palpate::ToolEventKind;
using palpate::ToolState;

namespace {

/// Where station @p station's gesture is anchored on a shared organ: the
/// "auto" anchor for station 1 (the compliance vertex farthest from the
/// attachment), then each next station at the compliance vertex farthest
/// from the anchors before it among those at least half as far from the
/// attachment as the first: spread over the free part of the organ.
std::uint32_t shared_anchor(const palpate::DrawnSurface& surface, int station) {
  const int n = surface.compliance_vertex_count;
  const auto drawn = static_cast<int>(surface.vertex_ids.size());
  auto at = [&](int j) {
    return Eigen::Vector3d(&surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
  };
  std::vector<double> from_fixed(static_cast<std::size_t>(n), 1e9);
  for (int j = 0; j < n; ++j)
    for (int f = n; f < drawn; ++f)
      from_fixed[static_cast<std::size_t>(j)] =
          std::min(from_fixed[static_cast<std::size_t>(j)], (at(j) - at(f)).norm());
  std::vector<int> anchors{palpate::auto_anchor(surface).drawn_index};
  const double reach = from_fixed[static_cast<std::size_t>(anchors[0])];
  while (static_cast<int>(anchors.size()) < station) {
    int best = anchors[0];
    double best_distance = -1;
    for (int j = 0; j < n; ++j) {
      if (from_fixed[static_cast<std::size_t>(j)] < reach / 2) continue;
      double nearest = 1e9;
      for (const int a : anchors) nearest = std::min(nearest, (at(j) - at(a)).norm());
      if (nearest > best_distance) {
        best_distance = nearest;
        best = j;
      }
    }
    anchors.push_back(best);
  }
  return surface.vertex_ids[static_cast<std::size_t>(anchors.back())];
}

/// A station: the gesture's tools on its model, at the haptic rate, from
/// the start time for @p seconds.
}  // namespace

int station_child(const Settings& s, int station, const std::string& role, double seconds,
                  const Rendezvous& rendezvous) {
  palpate::Gesture gesture = palpate::read_gesture_file(s.gesture_file);
  for (auto& t : gesture.tools) t.id = station_tool(station, t.id);
  const std::string model_id = station_model(s, station);
  palpate::ToolClient client(palpate::ToolClientOptions{});
  const auto timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(s.start_timeout_s * 1e3));
  const auto model = client.wait_for_model(model_id, timeout);
  if (!model) throw palpate::SystemError("no description of model " + model_id);
  const palpate::DrawnSurface& surface = model->surface;
  if (s.shared_organ) gesture.anchor_vertex_id = shared_anchor(surface, station);
  const palpate::GesturePlayer player(gesture, palpate::place_gesture(gesture, surface));
  for (int k = 0; k < player.tool_count(); ++k) client.open_tool(player.tool_id(k));
  if (!client.wait_for_daemon(timeout)) throw palpate::SystemError("palpated reads no tool poses");

  const int tools = player.tool_count();
  const double period_s = 1.0 / s.rate_hz;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s));
  const auto ticks_per_play =
      static_cast<std::size_t>(std::floor(player.duration_s() * s.rate_hz + 1e-9)) + 1;
  const auto total = static_cast<std::size_t>(std::llround(seconds * s.rate_hz));
  // Not in step: station k ticks (k − 1)/N of a period after station 1 and
  // plays its gesture from (k − 1)/N of its length.
  const double fraction = static_cast<double>(station - 1) / s.stations;
  const auto phase_ticks = static_cast<std::size_t>(fraction * static_cast<double>(ticks_per_play));
  std::vector<std::vector<TickRecord>> records(static_cast<std::size_t>(tools),
                                               std::vector<TickRecord>(total));
  std::vector<std::array<std::uint64_t, 6>> events(static_cast<std::size_t>(tools));
  std::array<palpate::ToolFeedbackSample, 64> late{};
  std::uint64_t other_sessions = 0;

  const std::int64_t start_ns = rendezvous.ready_then_wait_start();
  const auto start =
      steady_time(start_ns) + std::chrono::duration_cast<Clock::duration>(
                                  std::chrono::duration<double>(fraction * period_s));
  // Sequences from the steady clock in µs, as palpate-pliers: above those of
  // any earlier run of the same tools (the baseline's).
  const auto first_sequence = static_cast<std::uint64_t>(palpate::ToolClient::now_ns() / 1000);
  auto fill = [](TickRecord& r, const palpate::ToolFeedbackSample& f) {
    r.rtt_us = static_cast<float>(static_cast<double>(f.round_trip_ns()) * 1e-3);
    r.compute_us = static_cast<float>(static_cast<double>(f.compute_ns) * 1e-3);
    r.state = static_cast<std::uint8_t>(f.state);
    r.contacts = static_cast<std::uint8_t>(std::min<std::uint32_t>(f.contacts, 255));
  };
  auto collect_late = [&](int tool, std::size_t now_tick) {
    const std::string& id = player.tool_id(tool);
    for (;;) {
      const std::size_t n = client.take_late_feedback(id, late);
      for (std::size_t k = 0; k < n; ++k) {
        const auto& f = late[k];
        if (f.sequence < first_sequence || f.sequence > first_sequence + now_tick) {
          ++other_sessions;
          continue;
        }
        TickRecord& r = records[static_cast<std::size_t>(tool)][f.sequence - first_sequence];
        if (r.outcome != 0) continue;
        r.outcome = 2;
        fill(r, f);
      }
      if (n < late.size()) return;
    }
  };
  std::size_t played = 0;
  for (std::size_t i = 0; i < total; ++i, ++played) {
    const auto scheduled = start + i * period;
    std::this_thread::sleep_until(scheduled);
    const double t = static_cast<double>((i + phase_ticks) % ticks_per_play) * period_s;
    const std::uint64_t sequence = first_sequence + i;
    for (int k = 0; k < tools; ++k) {
      const palpate::GesturePose pose = player.sample(k, t);
      const auto& q = pose.orientation;
      const std::int64_t sent =
          client.send_pose(player.tool_id(k), model_id, sequence,
                           {pose.hinge_m.x(), pose.hinge_m.y(), pose.hinge_m.z()},
                           {q.w(), q.x(), q.y(), q.z()}, pose.jaw_angle_rad);
      records[static_cast<std::size_t>(k)][i].lag_us = static_cast<float>(
          static_cast<double>(sent - start_ns) * 1e-3 -
          std::chrono::duration<double, std::micro>(scheduled - steady_time(start_ns)).count());
    }
    const auto deadline = scheduled + period;
    for (int k = 0; k < tools; ++k) {
      TickRecord& r = records[static_cast<std::size_t>(k)][i];
      if (const auto f = client.wait_feedback(player.tool_id(k), sequence, deadline)) {
        if (f->sequence == sequence) {
          r.outcome = 1;
          fill(r, *f);
        } else {
          r.newer = 1;
        }
      }
      collect_late(k, i);
    }
    for (const auto& e : client.take_events()) {
      if (e.model_id != model_id || e.pose_sequence < first_sequence) continue;
      for (int k = 0; k < tools; ++k)
        if (player.tool_id(k) == e.tool_id && static_cast<std::size_t>(e.kind) < 6)
          ++events[static_cast<std::size_t>(k)][static_cast<std::size_t>(e.kind)];
    }
  }
  const auto drain_until = Clock::now() + std::chrono::milliseconds(20);
  for (int k = 0; k < tools && played > 0; ++k) {
    client.wait_feedback(player.tool_id(k), first_sequence + played, drain_until);
    collect_late(k, played - 1);
  }

  json tools_json = json::array();
  for (int k = 0; k < tools; ++k) {
    const std::string& id = player.tool_id(k);
    const fs::path file = fs::path(s.work) / (role + "-" + id + ".ticks");
    write_ticks(file, records[static_cast<std::size_t>(k)]);
    json ev = json::object();
    for (std::size_t kind = 0; kind < 6; ++kind)
      ev[palpate::tool_event_name(static_cast<ToolEventKind>(kind))] =
          events[static_cast<std::size_t>(k)][kind];
    tools_json.push_back({{"id", id},
                          {"model", model_id},
                          {"anchor_vertex", player.anchor(k).vertex_id},
                          {"ticks_file", file.filename().string()},
                          {"events", ev}});
  }
  write_json(fs::path(s.work) / (role + ".json"),
             {{"role", role},
              {"tools", tools_json},
              {"ticks", played},
              {"foreign_feedback", client.foreign_feedback()},
              {"dropped_late_feedback", client.dropped_late_feedback()},
              {"other_session_feedback", other_sessions}});
  return 0;
}

/// A viewer: every model's surface stream and the status heartbeat, with
/// palpate's QoS, counted from the start for @p seconds.
int viewer_child(const Settings& s, const std::string& role, double seconds,
                 const Rendezvous& rendezvous) {
  namespace dds = palpate::dds;
  const dds::Participant participant = dds::join_domain(0, "");
  const dds_entity_t p = participant.get();
  const dds_entity_t surface_reader = dds::check(
      dds_create_reader(p, dds::topic(p, &palpate_SurfaceDisplacement_desc, dds::kSurfaceTopic),
                        dds::surface_qos().get(), nullptr),
      "creating the surface reader");
  const dds_entity_t status_reader =
      dds::check(dds_create_reader(p, dds::topic(p, &palpate_DaemonStatus_desc, dds::kStatusTopic),
                                   dds::status_qos().get(), nullptr),
                 "creating the status reader");
  const dds::Entity waitset(dds::check(dds_create_waitset(p), "creating the waitset"));
  for (const dds_entity_t reader : {surface_reader, status_reader})
    dds::check(dds_waitset_attach(waitset.get(),
                                  dds::check(dds_create_readcondition(reader, DDS_ANY_STATE),
                                             "creating a read condition"),
                                  0),
               "attaching a read condition");
  const auto give_up =
      Clock::now() + std::chrono::milliseconds(static_cast<std::int64_t>(s.start_timeout_s * 1e3));
  for (;;) {
    dds_subscription_matched_status_t surface{}, status{};
    dds_get_subscription_matched_status(surface_reader, &surface);
    dds_get_subscription_matched_status(status_reader, &status);
    if (surface.current_count > 0 && status.current_count > 0) break;
    if (Clock::now() > give_up) throw palpate::SystemError("no surface or status writer");
    dds_sleepfor(DDS_MSECS(10));
  }

  struct PerModel {
    std::uint64_t samples = 0, gaps = 0, out_of_order = 0, last = 0, first = 0;
  };
  std::map<std::string, PerModel> models;
  std::vector<double> latency_us;  // source timestamp → taken, both UTC clocks of this host
  std::uint64_t heartbeats = 0;
  palpate_DaemonStatus last_status{};
  bool counting = false;
  auto take_all = [&] {
    constexpr int kBatch = 16;
    void* samples[kBatch] = {};
    dds_sample_info_t infos[kBatch];
    for (;;) {
      const dds_return_t n = dds_take(surface_reader, samples, infos, kBatch, kBatch);
      if (n < 0)
        throw palpate::SystemError(std::string("taking surface samples: ") + dds_strretcode(n));
      const dds_time_t now = dds_time();
      for (int i = 0; i < n; ++i) {
        if (!infos[i].valid_data) continue;
        const auto& d = *static_cast<const palpate_SurfaceDisplacement*>(samples[i]);
        PerModel& m = models[std::string(d.model_id, strnlen(d.model_id, sizeof d.model_id))];
        // Before the start: only where each stream stands.
        if (counting) {
          if (m.last != 0 && d.sequence_number > m.last + 1)
            m.gaps += d.sequence_number - m.last - 1;
          if (m.last != 0 && d.sequence_number <= m.last) ++m.out_of_order;
          if (m.samples++ == 0) m.first = d.sequence_number;
          latency_us.push_back(static_cast<double>(now - infos[i].source_timestamp) * 1e-3);
        }
        m.last = std::max(m.last, d.sequence_number);
      }
      if (n > 0) dds_return_loan(surface_reader, samples, n);
      if (n < kBatch) break;
    }
    for (;;) {
      void* sample = nullptr;
      dds_sample_info_t info;
      const dds_return_t n = dds_take(status_reader, &sample, &info, 1, 1);
      if (n <= 0) break;
      if (info.valid_data && counting) {
        ++heartbeats;
        std::memcpy(&last_status, sample, sizeof last_status);
      }
      dds_return_loan(status_reader, &sample, n);
    }
  };
  take_all();
  const std::int64_t start_ns = rendezvous.ready_then_wait_start();
  std::this_thread::sleep_until(steady_time(start_ns));
  take_all();
  for (auto& [id, m] : models) m.samples = 0;
  counting = true;
  const auto end = steady_time(start_ns) + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(seconds));
  while (Clock::now() < end) {
    dds_attach_t triggered;
    dds_waitset_wait(
        waitset.get(), &triggered, 1,
        std::chrono::duration_cast<std::chrono::nanoseconds>(end - Clock::now()).count());
    take_all();
  }
  json per_model = json::object();
  for (const auto& [id, m] : models)
    per_model[id] = {
        {"samples", m.samples},      {"rate_hz", static_cast<double>(m.samples) / seconds},
        {"sequence_gaps", m.gaps},   {"out_of_order", m.out_of_order},
        {"first_sequence", m.first}, {"last_sequence", m.last}};
  write_json(fs::path(s.work) / (role + ".json"),
             {{"role", role},
              {"models", per_model},
              {"latency", to_json(distribution(std::move(latency_us)))},
              {"heartbeats", heartbeats},
              {"last_status",
               {{"requests_served", last_status.requests_served},
                {"error_replies", last_status.error_replies},
                {"tool_poses", last_status.tool_poses},
                {"tool_poses_refused", last_status.tool_poses_refused},
                {"clients", last_status.clients},
                {"surface_rate_hz", last_status.surface_rate_hz},
                {"request_rate_hz", last_status.request_rate_hz}}}});
  return 0;
}

/// The requester: reliable constraint requests at a steady rate, one in
/// flight, each waited for up to --request-timeout.
int requester_child(const Settings& s, const std::string& role, double seconds,
                    const Rendezvous& rendezvous) {
  palpate::ClientOptions options;
  options.client_id = "load-requests";
  palpate::Client client(options);
  const auto timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(s.start_timeout_s * 1e3));
  // Per model: 12 patches of k = 1, 3, 5, 10 compliance vertices around
  // seeds spread over the surface, pushed 1.5 mm in along the outward normal.
  constexpr int kPatches = 12;
  constexpr std::array<int, 4> kSizes{1, 3, 5, 10};
  std::vector<std::vector<std::vector<palpate::ConstraintSpec>>> patches;
  const std::vector<std::string> models = model_ids(s);
  for (const std::string& model_id : models) {
    const auto model = client.wait_for_model(model_id, timeout);
    if (!model) throw palpate::SystemError("no description of model " + model_id);
    const palpate::DrawnSurface& surface = model->surface;
    const int n = model->surface.compliance_vertex_count;
    auto rest = [&](int j) {
      return Eigen::Vector3d(&model->surface.rest_positions_m[3 * static_cast<std::size_t>(j)]);
    };
    auto& mine = patches.emplace_back();
    for (int p = 0; p < kPatches; ++p) {
      const int seed = static_cast<int>(static_cast<long>(p) * n / kPatches);
      std::vector<int> order(static_cast<std::size_t>(n));
      for (int j = 0; j < n; ++j) order[static_cast<std::size_t>(j)] = j;
      const int k = std::min(n, kSizes[static_cast<std::size_t>(p) % kSizes.size()]);
      std::partial_sort(order.begin(), order.begin() + k, order.end(), [&](int a, int b) {
        return (rest(a) - rest(seed)).squaredNorm() < (rest(b) - rest(seed)).squaredNorm();
      });
      auto& patch = mine.emplace_back();
      for (int c = 0; c < k; ++c) {
        const int j = order[static_cast<std::size_t>(c)];
        const Eigen::Vector3d normal = palpate::outward_normal(surface, j);
        patch.push_back(palpate::ConstraintSpec::normal_displacement(
            model->surface.vertex_ids[static_cast<std::size_t>(j)],
            {normal.x(), normal.y(), normal.z()}, -0.0015));
      }
    }
  }
  if (!client.wait_for_service(timeout)) throw palpate::SystemError("palpated reads no requests");

  const std::int64_t start_ns = rendezvous.ready_then_wait_start();
  const auto start = steady_time(start_ns);
  const auto end =
      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / s.request_hz));
  const auto reply_timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(s.request_timeout_s * 1e3));
  std::vector<double> rtt_us;
  std::uint64_t sent = 0, ok = 0, errors = 0, lost = 0, behind = 0;
  std::string first_error;
  std::vector<std::uint64_t> lost_ids;
  auto next = start;
  for (std::uint64_t i = 0;; ++i) {
    std::this_thread::sleep_until(next);
    const auto sent_at = Clock::now();
    if (sent_at >= end) break;
    const auto& patch = patches[i % patches.size()][(i / patches.size()) % kPatches];
    const bool want_surface = i % 10 == 9;
    const std::uint64_t id =
        client.send(models[i % models.size()], patch, want_surface, /*update_state=*/false);
    ++sent;
    const auto reply = client.wait_reply(id, reply_timeout);
    if (!reply) {
      ++lost;
      if (lost_ids.size() < 20) lost_ids.push_back(id);
    } else {
      rtt_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - sent_at).count());
      const bool good = reply->status == palpate::RequestStatus::kOk &&
                        reply->results.size() == patch.size() &&
                        (!want_surface || !reply->surface_displacement_m.empty());
      if (good) {
        ++ok;
      } else {
        if (errors++ == 0)
          first_error = reply->message.empty() ? "wrong result count" : reply->message;
      }
    }
    // Steady: the next at its time, or now if this one ran late (no burst).
    next += period;
    if (next < Clock::now()) {
      ++behind;
      next = Clock::now();
    }
  }
  write_json(fs::path(s.work) / (role + ".json"),
             {{"role", role},
              {"sent", sent},
              {"ok", ok},
              {"errors", errors},
              {"first_error", first_error},
              {"lost", lost},
              {"lost_ids", lost_ids},
              {"sent_late", behind},
              {"rate_hz", static_cast<double>(sent) / seconds},
              {"timeout_s", s.request_timeout_s},
              {"foreign_replies", client.foreign_replies()},
              {"round_trip", to_json(distribution(std::move(rtt_us)))}});
  return 0;
}

}  // namespace palpate::load
