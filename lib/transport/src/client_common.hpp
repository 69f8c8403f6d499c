#pragma once
// Private to palpate_transport: what the two clients of palpated (Client,
// ToolClient) share: a reader with the waitset that wakes on its data, and
// the model descriptions (topic palpate_model, docs/dds.md).

#include <dds/dds.h>
#include <sched.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "palpate.h"
#include "palpate/core/error.hpp"
#include "palpate/transport/dds.hpp"
#include "palpate/transport/messages.hpp"
#include "palpate/transport/presence.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate::detail {

using ClientClock = std::chrono::steady_clock;

/// A reader and the waitset that wakes on its data.
struct WaitableReader {
  dds::Entity reader;
  dds::Entity waitset;

  WaitableReader() = default;
  /// A reader of @p topic under @p parent (the participant or a subscriber).
  WaitableReader(dds_entity_t participant, dds_entity_t parent, dds_entity_t topic,
                 const dds_qos_t* qos, const char* what) {
    reader = dds::Entity(dds::check(dds_create_reader(parent, topic, qos, nullptr), what));
    waitset = dds::Entity(dds::check(dds_create_waitset(participant), what));
    const dds_entity_t condition =
        dds::check(dds_create_readcondition(reader.get(), DDS_ANY_STATE), what);
    dds::check(dds_waitset_attach(waitset.get(), condition, 0), what);
  }

  bool busy_wait = false;  // poll instead of sleeping on the waitset

  /// Takes samples and hands each valid one to @p accept until it returns
  /// true (then true) or the deadline passes (then false). Takes what is
  /// there at least once, even with a deadline in the past.
  template <typename Sample, typename Accept>
  bool take_until(ClientClock::time_point deadline, Accept accept) {
    for (;;) {
      // One sample at a time: a batch would lose the samples after the
      // accepted one (two model descriptions arriving together, say).
      void* sample = nullptr;
      dds_sample_info_t info;
      const dds_return_t n = dds_take(reader.get(), &sample, &info, 1, 1);
      if (n < 0) throw SystemError(std::string("taking samples: ") + dds_strretcode(n));
      if (n > 0) {
        const bool done = info.valid_data && accept(*static_cast<const Sample*>(sample));
        dds_return_loan(reader.get(), &sample, n);
        if (done) return true;
        continue;
      }
      const auto now = ClientClock::now();
      if (now >= deadline) return false;
      if (busy_wait) {
        sched_yield();
        continue;
      }
      dds_attach_t triggered;
      dds_waitset_wait(
          waitset.get(), &triggered, 1,
          std::chrono::duration_cast<std::chrono::nanoseconds>(deadline - now).count());
    }
  }
};

/// palpated's presence from its status heartbeat (DaemonPresence, docs/faults.md).
/// poll() takes the heartbeats that came and allocates nothing. A heartbeat's
/// time is when it arrived (the reader's listener stamps it), not when it was
/// taken: a client that polls seldom does not take an old heartbeat for news.
class DaemonWatch {
 public:
  DaemonWatch() = default;
  /// A reader of @p status_topic (palpate_status) in @p participant.
  DaemonWatch(dds_entity_t participant, dds_entity_t status_topic,
              std::chrono::milliseconds timeout)
      : state_(std::make_unique<State>()) {
    state_->timeout_s = std::chrono::duration<double>(timeout).count();
    state_->listening.store(true, std::memory_order_release);
    dds_listener_t* listener = dds_create_listener(state_.get());
    dds_lset_data_available(listener, &DaemonWatch::on_heartbeat);
    const dds_entity_t reader =
        dds_create_reader(participant, status_topic, dds::status_qos().get(), listener);
    dds_delete_listener(listener);
    reader_ = dds::Entity(dds::check(reader, "creating the status reader"));
  }

  /// How many models the daemons heard so far serve, in all (from their
  /// last heartbeats); none before the first heartbeat.
  std::optional<std::size_t> models_served() const {
    if (!state_ || state_->daemons == 0) return std::nullopt;
    std::size_t total = 0;
    for (int i = 0; i < state_->daemons; ++i) total += state_->models[static_cast<std::size_t>(i)];
    return total;
  }

  const DaemonPresence& poll(ClientClock::time_point now) {
    State& s = *state_;
    void* samples[4] = {};
    dds_sample_info_t infos[4];
    for (;;) {
      const dds_return_t n = dds_take(reader_.get(), samples, infos, 4, 4);
      if (n <= 0) break;
      for (dds_return_t i = 0; i < n; ++i)
        if (infos[i].valid_data) heard(*static_cast<const palpate_DaemonStatus*>(samples[i]));
      dds_return_loan(reader_.get(), samples, n);
      if (n < 4) break;
    }
    DaemonPresence& p = s.presence;
    p.heartbeat_period_s = static_cast<double>(s.period_ns) * 1e-9;
    p.timeout_s =
        s.timeout_s > 0 ? s.timeout_s : 3 * (s.period_ns > 0 ? p.heartbeat_period_s : 1.0) + 1.0;
    if (s.heard_any) {
      const auto arrived = ClientClock::time_point(ClientClock::duration(s.last_arrival.load()));
      p.silent_s = std::max(0.0, std::chrono::duration<double>(now - arrived).count());
      const DaemonState state =
          p.silent_s > p.timeout_s ? DaemonState::kLost : DaemonState::kPresent;
      if (p.state == DaemonState::kPresent && state == DaemonState::kLost) ++p.losses;
      p.state = state;
    }
    return p;
  }

 private:
  struct State {
    double timeout_s = 0;                           // 0: automatic
    std::atomic<ClientClock::rep> last_arrival{0};  // steady clock, by the listener
    // State is complete before the listener's first call (released before
    // the reader is made, acquired by the listener), in C++'s memory model
    // and not only through Cyclone's internal ordering, which
    // ThreadSanitizer cannot see in the uninstrumented libddsc.
    std::atomic<bool> listening{false};
    bool heard_any = false;
    char daemon_id[64] = {};
    std::uint64_t last_uptime_ns = 0, period_ns = 0;
    DaemonPresence presence;
    // The models each daemon heard serves (fixed capacity: no allocation).
    static constexpr int kDaemons = 8;
    int daemons = 0;
    std::array<std::array<char, 64>, kDaemons> ids{};
    std::array<std::uint32_t, kDaemons> models{};
  };

  static void on_heartbeat(dds_entity_t, void* arg) {
    State& s = *static_cast<State*>(arg);
    (void)s.listening.load(std::memory_order_acquire);
    s.last_arrival.store(ClientClock::now().time_since_epoch().count());
  }

  void heard(const palpate_DaemonStatus& status) {
    State& s = *state_;
    int slot = 0;
    while (slot < s.daemons &&
           std::strncmp(s.ids[static_cast<std::size_t>(slot)].data(), status.daemon_id, 64) != 0)
      ++slot;
    if (slot == s.daemons && s.daemons < State::kDaemons) {
      std::memcpy(s.ids[static_cast<std::size_t>(slot)].data(), status.daemon_id, 64);
      ++s.daemons;
    }
    if (slot < s.daemons) s.models[static_cast<std::size_t>(slot)] = status.models;
    const bool same =
        s.heard_any && std::strncmp(status.daemon_id, s.daemon_id, sizeof s.daemon_id) == 0;
    if (!same) {
      std::memcpy(s.daemon_id, status.daemon_id, sizeof s.daemon_id);
      s.period_ns = 0;
    } else if (status.uptime_ns < s.last_uptime_ns) {
      ++s.presence.restarts;  // a new process: its uptime starts again
      s.period_ns = 0;
    } else if (status.uptime_ns > s.last_uptime_ns) {
      // Consecutive heartbeats of one process: its period (the smallest gap:
      // a keep-last-1 reader polled seldom skips some).
      const std::uint64_t gap = status.uptime_ns - s.last_uptime_ns;
      s.period_ns = s.period_ns == 0 ? gap : std::min(s.period_ns, gap);
    }
    s.last_uptime_ns = status.uptime_ns;
    s.presence.uptime_s = static_cast<double>(status.uptime_ns) * 1e-9;
    if (!s.heard_any || s.last_arrival.load() == 0)
      s.last_arrival.store(ClientClock::now().time_since_epoch().count());
    s.heard_any = true;
  }

  std::unique_ptr<State> state_;  // its address is the listener's argument
  dds::Entity reader_;            // declared after state_: deleted first
};

/// The model descriptions a client has seen (palpate_model: reliable,
/// transient-local, so a late joiner gets every served model).
class ModelDescriptions {
 public:
  ModelDescriptions() = default;
  /// Creates the topic and the reader in @p participant.
  explicit ModelDescriptions(dds_entity_t participant) {
    const dds_entity_t topic =
        dds::check(dds_create_topic(participant, &palpate_ModelDescription_desc, dds::kModelTopic,
                                    nullptr, nullptr),
                   "creating topic palpate_model");
    reader_ = WaitableReader(participant, participant, topic, dds::model_qos().get(),
                             "creating the model reader");
  }

  /// The description of @p model_id, waiting for it until @p deadline;
  /// std::nullopt if it did not come. Every description taken on the way is
  /// kept. With @p watch, the wait ends early once every model the daemons
  /// heard say they serve has been described and none is @p model_id: an
  /// unknown model is answered within about one heartbeat, not at the
  /// deadline.
  std::optional<ModelInfo> wait_for(const std::string& model_id, ClientClock::time_point deadline,
                                    DaemonWatch* watch = nullptr) {
    if (auto m = find(model_id)) return m;
    for (;;) {
      const auto now = ClientClock::now();
      const auto slice = watch ? std::min(deadline, now + std::chrono::milliseconds(50)) : deadline;
      const bool found = reader_.take_until<palpate_ModelDescription>(
          slice, [&](const palpate_ModelDescription& d) {
            ModelInfo info = wire::from_idl(d);
            const bool wanted = info.model_id == model_id;
            known_[info.model_id] = std::move(info);
            return wanted;
          });
      if (found || ClientClock::now() >= deadline) return find(model_id);
      if (watch) {
        watch->poll(ClientClock::now());
        if (const auto served = watch->models_served(); served && known_.size() >= *served)
          return std::nullopt;  // all described, and not this one
      }
    }
  }

  /// Ids of the models whose description has been taken, sorted.
  std::vector<std::string> known_ids() const {
    std::vector<std::string> ids;
    for (const auto& [id, info] : known_) ids.push_back(id);
    return ids;
  }

 private:
  std::optional<ModelInfo> find(const std::string& model_id) const {
    if (auto it = known_.find(model_id); it != known_.end()) return it->second;
    return std::nullopt;
  }

  WaitableReader reader_;
  std::map<std::string, ModelInfo> known_;
};

}  // namespace palpate::detail
