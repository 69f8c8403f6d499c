#pragma once
// Private to palpate_transport: what the two clients of palpated (Client,
// ToolClient) share: a reader with the waitset that wakes on its data, and
// the model descriptions (topic palpate_model, docs/dds.md).

#include <dds/dds.h>
#include <sched.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "palpate.h"
#include "palpate/client.hpp"
#include "palpate/dds.hpp"
#include "palpate/error.hpp"

namespace palpate::detail {

using ClientClock = std::chrono::steady_clock;

/// A bounded IDL string (char[N], not necessarily terminated) as a std::string.
inline std::string bounded(const char* text, std::size_t size) {
  return {text, strnlen(text, size)};
}

template <typename T, std::size_t N>
std::array<T, N> to_array(const T (&values)[N]) {
  std::array<T, N> a;
  std::copy_n(values, N, a.begin());
  return a;
}

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
  /// std::nullopt if it did not come. Every description taken on the way is kept.
  std::optional<ModelInfo> wait_for(const std::string& model_id, ClientClock::time_point deadline) {
    if (auto m = find(model_id)) return m;
    reader_.take_until<palpate_ModelDescription>(deadline, [&](const palpate_ModelDescription& d) {
      ModelInfo info = from_idl(d);
      const bool wanted = info.model_id == model_id;
      known_[info.model_id] = std::move(info);
      return wanted;
    });
    return find(model_id);
  }

  /// Ids of the models whose description has been taken, sorted.
  std::vector<std::string> known_ids() const {
    std::vector<std::string> ids;
    for (const auto& [id, info] : known_) ids.push_back(id);
    return ids;
  }

  static ModelInfo from_idl(const palpate_ModelDescription& d) {
    ModelInfo info;
    info.model_id = bounded(d.model_id, sizeof d.model_id);
    info.units = bounded(d.units, sizeof d.units);
    info.material_summary = bounded(d.material_summary, sizeof d.material_summary);
    info.input_hash = bounded(d.input_hash, sizeof d.input_hash);
    info.compliance_vertex_count = static_cast<int>(d.compliance_vertex_count);
    info.vertex_ids.assign(d.vertex_ids._buffer, d.vertex_ids._buffer + d.vertex_ids._length);
    info.rest_positions_m.assign(d.rest_positions._buffer,
                                 d.rest_positions._buffer + d.rest_positions._length);
    info.triangles.assign(d.triangles._buffer, d.triangles._buffer + d.triangles._length);
    return info;
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
