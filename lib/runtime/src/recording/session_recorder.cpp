#include "palpate/runtime/session_recorder.hpp"

#include <fmt/format.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <set>
#include <thread>

#include "palpate/core/error.hpp"
#include "palpate/core/ids.hpp"
#include "palpate/core/version.hpp"
#include "palpate/file/atomic_file.hpp"
#include "palpate/file/detail/hdf5_support.hpp"
#include "palpate/runtime/recording/session_streams.hpp"

namespace palpate {

namespace {

using detail::EventStream;
using detail::iso_utc;
using detail::kFormatName;
using detail::kFormatVersion;
using detail::SessionFile;
using detail::ToolStream;
using detail::unix_now_ns;
using hdf5::check;
using hdf5::Handle;
using hdf5::write_double_attribute;
using hdf5::write_int64_attribute;
using hdf5::write_int_attribute;
using hdf5::write_string_attribute;
using hdf5::write_strings_attribute;
using hdf5::write_uint64_attribute;

void validate(const std::filesystem::path& file, const std::filesystem::path& partial,
              const SessionInfo& info, const RecorderLimits& limits) {
  const std::string where = fmt::format("session recording '{}'", file.string());
  if (file.filename().empty())
    throw InputError(fmt::format("{}: names no file; give a file name such as session.h5", where));
  const auto dir = file.has_parent_path() ? file.parent_path() : std::filesystem::path(".");
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec))
    throw InputError(fmt::format("{}: directory '{}' does not exist; create it or record elsewhere",
                                 where, dir.string()));
  if (::access(dir.c_str(), W_OK) != 0)
    throw InputError(
        fmt::format("{}: directory '{}' is not writable by this process; fix its permissions or "
                    "record elsewhere",
                    where, dir.string()));
  if (std::filesystem::exists(file, ec))
    throw InputError(fmt::format(
        "{}: the file already exists; a recording is never overwritten: choose another name",
        where));
  if (std::filesystem::exists(partial, ec))
    throw InputError(fmt::format(
        "{}: '{}' exists (a recording in progress, or left by a crash and readable up to its last "
        "flush); move it away or choose another name",
        where, partial.string()));
  if (info.tools.empty()) throw InputError(fmt::format("{}: the session has no tools", where));
  std::set<std::string> ids;
  for (const auto& tool : info.tools) {
    if (!is_valid_id(tool.id) || tool.id == ".")
      throw InputError(fmt::format(
          "{}: tool id '{}' is not 1 to 63 characters among A-Z a-z 0-9 _ - .", where, tool.id));
    if (!ids.insert(tool.id).second)
      throw InputError(fmt::format("{}: tool id '{}' appears twice", where, tool.id));
  }
  if (limits.ring_ticks < 1 || limits.ring_events < 1 || limits.ring_rendered < 1 ||
      limits.ring_contacts < limits.max_contacts_per_tick || !(limits.flush_interval_s > 0) ||
      !(limits.write_interval_s > 0))
    throw InputError(
        fmt::format("{}: recorder limits need ring_ticks ≥ 1, ring_events ≥ 1, ring_rendered ≥ 1, "
                    "ring_contacts ≥ "
                    "max_contacts_per_tick, flush_interval_s > 0 and write_interval_s > 0",
                    where));
}

}  // namespace

struct SessionRecorder::Impl {
  struct TickSlot {
    ToolTickRecord tick;
    std::uint64_t contact_begin;  // position in the contact ring
    std::uint32_t contact_count;
    bool truncated;
  };
  struct EventSlot {
    double time_s;
    std::int32_t tool;
    std::int32_t kind;
    std::uint64_t pose_sequence;
  };

  using RenderedSlot = RenderedRecord;

  Impl(std::filesystem::path final_path, const RecorderLimits& l, std::size_t tools)
      : path(std::move(final_path)),
        partial(path.string() + ".partial"),
        limits(l),
        tool_count(tools),
        // Value-initialized: the pages are touched now, not by the real-time side.
        ticks(std::make_unique<TickSlot[]>(l.ring_ticks)),
        contact_vertices(std::make_unique<std::uint32_t[]>(l.ring_contacts)),
        contact_forces(std::make_unique<double[]>(3 * l.ring_contacts)),
        events(std::make_unique<EventSlot[]>(l.ring_events)),
        rendered(std::make_unique<RenderedSlot[]>(l.ring_rendered)),
        dropped_per_tool(std::make_unique<std::atomic<std::uint64_t>[]>(tools)) {}

  void create(const SessionInfo& info);
  void run_writer() noexcept;
  void drain();
  void finish();

  std::filesystem::path path, partial;
  RecorderLimits limits;
  std::size_t tool_count;
  // The file: the constructor's thread, then the writer thread, then close()'s
  // thread after joining it.
  std::unique_ptr<SessionFile> file;

  // Rings with one producer and one consumer. Positions grow without bound;
  // a slot is position mod capacity. The producer publishes a slot with a
  // release store of its head, the consumer frees it with one of its tail.
  std::unique_ptr<TickSlot[]> ticks;
  std::unique_ptr<std::uint32_t[]> contact_vertices;
  std::unique_ptr<double[]> contact_forces;  // 3 per contact
  std::unique_ptr<EventSlot[]> events;
  std::unique_ptr<RenderedSlot[]> rendered;
  std::unique_ptr<std::atomic<std::uint64_t>[]> dropped_per_tool;
  alignas(64) std::atomic<std::uint64_t> tick_head{0};
  std::uint64_t contact_head = 0;  // the producer's alone
  std::atomic<std::uint64_t> event_head{0};
  std::atomic<std::uint64_t> rendered_head{0};
  std::atomic<std::uint64_t> recorded{0}, dropped{0}, dropped_events{0}, dropped_rendered{0};
  std::atomic<bool> accepting{true};
  alignas(64) std::atomic<std::uint64_t> tick_tail{0};
  std::atomic<std::uint64_t> contact_tail{0};
  std::atomic<std::uint64_t> event_tail{0};
  std::atomic<std::uint64_t> rendered_tail{0};
  std::atomic<std::uint64_t> flushed{0};
  std::atomic<bool> failed{false};

  std::mutex mutex;  // guards stop and error; wakes the writer
  std::condition_variable wake;
  bool stop = false;
  std::string error;
  bool closed = false;
  std::thread writer;
};

void SessionRecorder::Impl::create(const SessionInfo& info) {
  hdf5::silence_hdf5();
  auto f = std::make_unique<SessionFile>(
      SessionFile{Handle(H5Fcreate(partial.c_str(), H5F_ACC_EXCL, H5P_DEFAULT, H5P_DEFAULT),
                         H5Fclose, fmt::format("create {}", partial.string())),
                  {},
                  {},
                  0});
  const hid_t root = f->file;
  write_string_attribute(root, "format", kFormatName);
  write_int_attribute(root, "format_version", kFormatVersion);
  write_string_attribute(root, "producer", "palpate " PALPATE_VERSION);
  write_string_attribute(root, "model_id", info.model_id);
  write_string_attribute(root, "model_file", info.model_file);
  write_string_attribute(root, "input_hash", info.input_hash);
  write_string_attribute(root, "daemon_id", info.daemon_id);
  write_int64_attribute(root, "start_unix_ns", info.start_unix_ns);
  write_string_attribute(root, "started_utc", iso_utc(info.start_unix_ns));
  write_string_attribute(root, "units", "m, N, s, rad");
  write_uint64_attribute(root, "max_contacts_per_tick", limits.max_contacts_per_tick);
  write_double_attribute(root, "flush_interval_s", limits.flush_interval_s);

  Handle tools = hdf5::group(root, "tools");
  std::vector<std::string> ids;
  for (const auto& t : info.tools) ids.push_back(t.id);
  write_strings_attribute(tools, "ids", ids);
  const ContactSettings& c = info.contact;
  write_double_attribute(tools, "watchdog_timeout_s", c.watchdog_timeout_s);
  write_double_attribute(tools, "watchdog_ramp_s", c.watchdog_ramp_s);
  write_double_attribute(tools, "search_margin_m", c.search_margin_m);
  write_int_attribute(tools, "max_contacts_per_tool", c.max_contacts_per_tool);
  write_int_attribute(tools, "max_iterations", c.max_iterations);
  write_double_attribute(tools, "workspace_margin_m", c.workspace_margin_m);
  for (std::size_t i = 0; i < info.tools.size(); ++i)
    f->tools.push_back(std::make_unique<ToolStream>(tools, info.tools[i], static_cast<int>(i)));
  f->events = std::make_unique<EventStream>(root);
  // From now on the partial file is readable, if empty.
  check(H5Fflush(root, H5F_SCOPE_LOCAL), fmt::format("flush {}", partial.string()));
  file = std::move(f);
}

void SessionRecorder::Impl::drain() {
  SessionFile& f = *file;
  const std::uint64_t tick_end = tick_head.load(std::memory_order_acquire);
  std::uint64_t tick = tick_tail.load(std::memory_order_relaxed);
  const std::uint64_t staged_ticks = tick_end - tick;
  std::uint64_t contact_end = contact_tail.load(std::memory_order_relaxed);
  for (; tick != tick_end; ++tick) {
    const TickSlot& slot = ticks[tick % limits.ring_ticks];
    f.tools[static_cast<std::size_t>(slot.tick.tool)]->stage(
        slot.tick, slot.contact_count, slot.truncated, [&](std::uint32_t i) {
          const std::size_t c = (slot.contact_begin + i) % limits.ring_contacts;
          return std::pair<std::uint32_t, const double*>(contact_vertices[c],
                                                         &contact_forces[3 * c]);
        });
    contact_end = slot.contact_begin + slot.contact_count;
  }
  contact_tail.store(contact_end, std::memory_order_release);
  tick_tail.store(tick_end, std::memory_order_release);

  const std::uint64_t event_end = event_head.load(std::memory_order_acquire);
  for (std::uint64_t e = event_tail.load(std::memory_order_relaxed); e != event_end; ++e) {
    const EventSlot& slot = events[e % limits.ring_events];
    f.events->time_s.stage(slot.time_s);
    f.events->tool.stage(slot.tool);
    f.events->kind.stage(slot.kind);
    f.events->pose_sequence.stage(slot.pose_sequence);
    ++f.events->count;
  }
  event_tail.store(event_end, std::memory_order_release);

  const std::uint64_t rendered_end = rendered_head.load(std::memory_order_acquire);
  for (std::uint64_t k = rendered_tail.load(std::memory_order_relaxed); k != rendered_end; ++k) {
    const RenderedSlot& slot = rendered[k % limits.ring_rendered];
    f.tools[static_cast<std::size_t>(slot.tool)]->stage(slot);
  }
  rendered_tail.store(rendered_end, std::memory_order_release);

  // The rings are free again before the (slow) writes.
  for (auto& t : f.tools) t->write();
  f.events->write();
  f.ticks += staged_ticks;
}

void SessionRecorder::Impl::run_writer() noexcept {
  hdf5::silence_hdf5();
  using Clock = std::chrono::steady_clock;
  // Capped so that a huge interval (tests: "never") does not overflow the clock.
  const auto interval = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(std::min(limits.write_interval_s, 1e6)));
  const auto flush_interval = std::chrono::duration<double>(limits.flush_interval_s);
  auto last_flush = Clock::now();
  std::unique_lock lock(mutex);
  for (;;) {
    wake.wait_for(lock, interval, [&] { return stop; });
    const bool stopping = stop;
    lock.unlock();
    try {
      drain();
      if (!stopping && Clock::now() - last_flush >= flush_interval) {
        check(H5Fflush(file->file, H5F_SCOPE_LOCAL), fmt::format("flush {}", partial.string()));
        flushed.store(file->ticks, std::memory_order_relaxed);
        last_flush = Clock::now();
      }
    } catch (const std::exception& e) {
      accepting.store(false, std::memory_order_relaxed);
      failed.store(true, std::memory_order_relaxed);
      lock.lock();
      error = e.what();
      return;
    }
    if (stopping) return;
    lock.lock();
  }
}

void SessionRecorder::Impl::finish() {
  SessionFile& f = *file;
  double duration_s = 0;
  for (std::size_t i = 0; i < f.tools.size(); ++i) {
    const ToolStream& t = *f.tools[i];
    t.summary.write(t.group, dropped_per_tool[i].load(std::memory_order_relaxed));
    write_uint64_attribute(t.group, "rendered_steps", t.rendered_steps);
    write_double_attribute(t.group, "max_rendered_force_n", t.max_rendered_force);
    write_double_attribute(t.group, "max_rendered_damping", t.max_damping);
    if (t.summary.ticks > 0) duration_s = std::max(duration_s, t.summary.last_time_s);
  }
  const hid_t root = f.file;
  write_string_attribute(root, "closed_utc", iso_utc(unix_now_ns()));
  write_double_attribute(root, "duration_s", duration_s);
  write_uint64_attribute(root, "ticks", f.ticks);
  write_uint64_attribute(root, "events", f.events->count);
  write_uint64_attribute(root, "dropped_ticks", dropped.load(std::memory_order_relaxed));
  write_uint64_attribute(root, "dropped_events", dropped_events.load(std::memory_order_relaxed));
  write_uint64_attribute(root, "dropped_rendered",
                         dropped_rendered.load(std::memory_order_relaxed));
  check(H5Fflush(root, H5F_SCOPE_LOCAL), fmt::format("flush {}", partial.string()));
  f.tools.clear();
  f.events.reset();
  if (!f.file.reset()) throw SystemError(fmt::format("HDF5: cannot close {}", partial.string()));
  file.reset();
  durable_rename(partial, path);
}

SessionRecorder::SessionRecorder(std::filesystem::path file, SessionInfo info,
                                 RecorderLimits limits) {
  const std::filesystem::path partial = file.string() + ".partial";
  validate(file, partial, info, limits);
  impl_ = std::make_unique<Impl>(std::move(file), limits, info.tools.size());
  try {
    impl_->create(info);
  } catch (const SystemError& e) {
    impl_->file.reset();
    std::error_code ec;
    std::filesystem::remove(partial, ec);
    throw InputError(
        fmt::format("session recording '{}': cannot create '{}' ({}); check the disk "
                    "and the directory's permissions",
                    impl_->path.string(), partial.string(), e.what()));
  }
  impl_->writer = std::thread([r = impl_.get()] { r->run_writer(); });
}

SessionRecorder::~SessionRecorder() {
  try {
    close();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate: %s\n", e.what());
  }
}

bool SessionRecorder::record(const ToolTickRecord& tick,
                             std::span<const std::uint32_t> contact_vertex_ids,
                             std::span<const double> contact_forces_n) {
  Impl& r = *impl_;
  if (!r.accepting.load(std::memory_order_relaxed) || tick.tool < 0 ||
      static_cast<std::size_t>(tick.tool) >= r.tool_count) {
    r.dropped.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  assert(contact_forces_n.size() == 3 * contact_vertex_ids.size());
  const std::size_t given = std::min(contact_vertex_ids.size(), contact_forces_n.size() / 3);
  const std::size_t n = std::min(given, r.limits.max_contacts_per_tick);
  const std::uint64_t head = r.tick_head.load(std::memory_order_relaxed);
  if (head - r.tick_tail.load(std::memory_order_acquire) >= r.limits.ring_ticks ||
      r.contact_head + n - r.contact_tail.load(std::memory_order_acquire) >
          r.limits.ring_contacts) {
    r.dropped.fetch_add(1, std::memory_order_relaxed);
    r.dropped_per_tool[static_cast<std::size_t>(tick.tool)].fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  Impl::TickSlot& slot = r.ticks[head % r.limits.ring_ticks];
  slot.tick = tick;
  slot.contact_begin = r.contact_head;
  slot.contact_count = static_cast<std::uint32_t>(n);
  slot.truncated = n < contact_vertex_ids.size();
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t c = (r.contact_head + i) % r.limits.ring_contacts;
    r.contact_vertices[c] = contact_vertex_ids[i];
    std::copy_n(&contact_forces_n[3 * i], 3, &r.contact_forces[3 * c]);
  }
  r.contact_head += n;
  r.tick_head.store(head + 1, std::memory_order_release);
  r.recorded.fetch_add(1, std::memory_order_relaxed);
  return true;
}

bool SessionRecorder::record_event(double time_s, std::int32_t tool, ToolEventKind kind,
                                   std::uint64_t pose_sequence) {
  Impl& r = *impl_;
  const std::uint64_t head = r.event_head.load(std::memory_order_relaxed);
  if (!r.accepting.load(std::memory_order_relaxed) || tool < 0 ||
      static_cast<std::size_t>(tool) >= r.tool_count ||
      head - r.event_tail.load(std::memory_order_acquire) >= r.limits.ring_events) {
    r.dropped_events.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  r.events[head % r.limits.ring_events] = {time_s, tool, static_cast<std::int32_t>(kind),
                                           pose_sequence};
  r.event_head.store(head + 1, std::memory_order_release);
  return true;
}

bool SessionRecorder::record_rendered(const RenderedRecord& step) {
  Impl& r = *impl_;
  const std::uint64_t head = r.rendered_head.load(std::memory_order_relaxed);
  if (!r.accepting.load(std::memory_order_relaxed) || step.tool < 0 ||
      static_cast<std::size_t>(step.tool) >= r.tool_count ||
      head - r.rendered_tail.load(std::memory_order_acquire) >= r.limits.ring_rendered) {
    r.dropped_rendered.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  r.rendered[head % r.limits.ring_rendered] = step;
  r.rendered_head.store(head + 1, std::memory_order_release);
  return true;
}

void SessionRecorder::close() {
  Impl& r = *impl_;
  if (r.closed) return;
  r.closed = true;
  r.accepting.store(false, std::memory_order_relaxed);
  {
    std::lock_guard lock(r.mutex);
    r.stop = true;
  }
  r.wake.notify_one();
  r.writer.join();
  hdf5::silence_hdf5();
  const std::string kept =
      fmt::format("what was written up to then is in '{}'", r.partial.string());
  if (r.failed.load(std::memory_order_relaxed)) {
    r.file.reset();
    throw SystemError(
        fmt::format("session recording '{}': {}; {}", r.path.string(), r.error, kept));
  }
  try {
    r.finish();
  } catch (const std::exception& e) {
    r.file.reset();
    throw SystemError(
        fmt::format("session recording '{}': {}; {}", r.path.string(), e.what(), kept));
  }
}

std::uint64_t SessionRecorder::recorded() const {
  return impl_->recorded.load(std::memory_order_relaxed);
}
std::uint64_t SessionRecorder::dropped() const {
  return impl_->dropped.load(std::memory_order_relaxed);
}
std::uint64_t SessionRecorder::dropped_events() const {
  return impl_->dropped_events.load(std::memory_order_relaxed);
}
std::uint64_t SessionRecorder::dropped_rendered() const {
  return impl_->dropped_rendered.load(std::memory_order_relaxed);
}
std::uint64_t SessionRecorder::flushed() const {
  return impl_->flushed.load(std::memory_order_relaxed);
}
bool SessionRecorder::failed() const { return impl_->failed.load(std::memory_order_relaxed); }
const std::filesystem::path& SessionRecorder::path() const { return impl_->path; }

}  // namespace palpate
