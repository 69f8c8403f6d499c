#pragma once
/// @file
/// Records a haptic session to HDF5 for assessing a trainee's gesture: every
/// tool's poses, feedback and contacts, the tools' events, and per-tool
/// summaries (time in contact, maximum force, path length...). The layout is
/// documented in docs/session-recording.md.
///
/// The real-time side (record(), record_event()) copies into preallocated
/// rings; a writer thread appends them to the file in batches and flushes it
/// every flush_interval_s, so a crash loses at most the samples since the
/// last flush. The file is written as "<file>.partial" and renamed to
/// "<file>" by close().

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "palpate/runtime/tool_geometry.hpp"
#include "palpate/runtime/tool_state.hpp"

namespace palpate {

/// What the file says about the session, written when it starts.
struct SessionInfo {
  std::string model_id;    ///< the organ's id in palpated
  std::string model_file;  ///< its compliance file
  std::string input_hash;  ///< the compliance file's input_hash
  std::string daemon_id;
  std::vector<ToolGeometry> tools;  ///< index = ToolTickRecord::tool; ids must be distinct
  ContactSettings contact;
  std::int64_t start_unix_ns = 0;  ///< UTC wall clock at session start, ns since 1970
};

/// One feedback sample of one tool.
struct ToolTickRecord {
  double time_s = 0;              ///< since session start (the daemon's steady clock), s
  std::int32_t tool = 0;          ///< index into SessionInfo::tools
  std::uint64_t sequence = 0;     ///< the pose's sequence
  std::int64_t send_time_ns = 0;  ///< the client's clock, as in the pose, ns
  double position_m[3]{};         ///< hinge, model frame, m
  double orientation_wxyz[4]{};   ///< unit quaternion tool → model
  double jaw_angle_rad = 0;
  double force_n[3]{};    ///< feedback sent to the device: force on the tool, N
  double torque_nm[3]{};  ///< about the hinge, N·m
  double grip_n = 0;      ///< per jaw, N
  ToolState state = ToolState::kFree;
  bool watchdog = false, force_limited = false;
  std::uint32_t held = 0;        ///< surface points held by the jaws
  std::uint64_t compute_ns = 0;  ///< time the daemon spent on this tick, ns
};

/// What a device rendered at one step of its own loop, at its own rate
/// (ToolClient::render(), reported with its poses; docs/session-recording.md,
/// "What the device rendered").
struct RenderedRecord {
  std::int32_t tool = 0;              ///< index into SessionInfo::tools
  std::int64_t time_ns = 0;           ///< the client's clock, as send_time_ns, ns
  std::uint64_t answer_sequence = 0;  ///< the pose the rendered answer answers (0: none yet)
  double position_m[3]{};             ///< the device's hinge, model frame, m
  double force_n[3]{};                ///< rendered on the hand, model frame, N
  double damping = 0;                 ///< added by the passivity controller, N·s/m
};

/// Sizes and cadence of a recorder. Memory: ring_ticks × ~200 B +
/// ring_contacts × 28 B + ring_events × 24 B + ring_rendered × 80 B
/// (defaults: 6.6 + 7.3 + 5.2 MB).
struct RecorderLimits {
  std::size_t ring_ticks = 1 << 15;  ///< ticks waiting for the writer (16 s of 2 tools at 1 kHz)
  std::size_t max_contacts_per_tick = 64;  ///< contacts kept per tick; more are cut (counted)
  double flush_interval_s = 1.0;           ///< H5Fflush at most this often: what a crash can lose
  std::size_t ring_contacts = 1 << 18;     ///< contacts waiting for the writer
  std::size_t ring_events = 1 << 12;       ///< events waiting for the writer
  std::size_t ring_rendered = 1 << 16;     ///< rendered steps waiting (8 s of 2 tools at 4 kHz)
  double write_interval_s = 0.1;           ///< the writer appends the rings to the file this often
};

/// A session file being written. One producer at a time calls record() and
/// record_event() (the caller serializes them, possibly from several threads
/// under its own mutex); close() must not run concurrently with them: detach
/// the recorder under that mutex and close it outside, so the real-time
/// side never waits for the final write.
class SessionRecorder {
 public:
  /// Creates "<file>.partial", writes the session attributes and every
  /// dataset (empty), flushes it and starts the writer thread.
  /// @throws InputError if the directory does not exist or is not writable,
  ///   if "<file>" or "<file>.partial" already exists (a recording is never
  ///   overwritten), if a tool id is not a valid id or repeats, or if the
  ///   limits are not positive; the message names the path and what to do.
  /// @throws SystemError if HDF5 fails.
  SessionRecorder(std::filesystem::path file, SessionInfo info, RecorderLimits limits = {});
  /// close() if not closed; never throws (an error is printed on stderr).
  ~SessionRecorder();
  SessionRecorder(const SessionRecorder&) = delete;
  SessionRecorder& operator=(const SessionRecorder&) = delete;

  /// Real-time side: copies the tick and its contacts into the rings. Never
  /// blocks on I/O, never allocates, never throws.
  /// @param contact_vertex_ids mesh vertex ids of the tool's contacts
  /// @param contact_forces_n force on the organ at each, 3 per contact, N
  ///   (3 × contact_vertex_ids.size() values)
  /// @returns false, counting the tick as dropped, when the rings are full,
  ///   the tool index is out of range or the recorder is closed. Contacts
  ///   beyond max_contacts_per_tick are not recorded (the tick is, and
  ///   counted in the tool's truncated_contact_ticks).
  bool record(const ToolTickRecord& tick, std::span<const std::uint32_t> contact_vertex_ids,
              std::span<const double> contact_forces_n);
  /// Real-time side, like record(): one event of tool @p tool at @p time_s
  /// (the session clock), answering pose @p pose_sequence.
  bool record_event(double time_s, std::int32_t tool, ToolEventKind kind,
                    std::uint64_t pose_sequence);
  /// Real-time side, like record(): one step of what a device rendered.
  bool record_rendered(const RenderedRecord& step);

  /// Writes what the rings hold, the per-tool summaries and the closing
  /// attributes, closes the file and renames "<file>.partial" to "<file>".
  /// Idempotent: later calls do nothing.
  /// @throws SystemError on an I/O failure (now or earlier in the writer
  ///   thread); "<file>.partial" then keeps what was written.
  void close();

  /// Ticks accepted by record() (written, or waiting in the ring).
  std::uint64_t recorded() const;
  /// Ticks record() refused.
  std::uint64_t dropped() const;
  /// Events record_event() refused.
  std::uint64_t dropped_events() const;
  /// Rendered steps record_rendered() refused.
  std::uint64_t dropped_rendered() const;
  /// Ticks in the file as of its last flush: what a crash now would keep.
  std::uint64_t flushed() const;
  /// The writer thread stopped on an I/O error (close() will throw it);
  /// record() drops every tick from then on.
  bool failed() const;
  /// The final path ("<file>"); the partial one is path() + ".partial".
  const std::filesystem::path& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate
