#include "device_handle.hpp"

#include <algorithm>
#include <chrono>
#include <cstddef>

namespace {

/// An answer as the C API's log keeps it (palpate_device_answer, version 1.0).
palpate_device_answer to_answer(const palpate::ToolFeedbackSample& s) {
  palpate_device_answer a{};
  a.struct_size = sizeof a;
  a.sequence = s.sequence;
  a.send_time_ns = s.send_time_ns;
  a.receive_time_ns = s.receive_time_ns;
  std::copy(s.force_n.begin(), s.force_n.end(), a.force_n);
  std::copy(s.torque_nm.begin(), s.torque_nm.end(), a.torque_nm);
  a.grip_n = s.grip_n;
  a.contacts = s.contacts;
  a.tool_state = static_cast<int>(s.state);
  a.force_limited = s.force_limited ? 1 : 0;
  a.watchdog = s.watchdog ? 1 : 0;
  a.compute_ns = s.compute_ns;
  a.model_valid = s.local.valid ? 1 : 0;
  return a;
}

}  // namespace

void palpate_device::took(const palpate::ToolFeedbackSample& s) {
  ++answers_taken;
  if (!answers.push(to_answer(s))) ++answers_dropped;
  if (!has_answer || s.sequence >= newest.sequence) {
    newest = s;
    has_answer = true;
  }
}

void palpate_device::drain() {
  if (poses_sent == 0) return;
  while (next_sequence <= sequence) {
    const auto s =
        client.wait_feedback(tool_id, next_sequence, std::chrono::steady_clock::time_point{});
    if (!s) break;
    took(*s);
    next_sequence = s->sequence + 1;
  }
  for (;;) {
    const std::size_t n = client.take_late_feedback(tool_id, late);
    for (std::size_t i = 0; i < n; ++i) took(late[i]);
    if (n < late.size()) break;
  }
}
