#pragma once
/// @file
/// The DDS side of palpate-viewer: a participant that reads what palpated
/// publishes for viewers (models, surface stream, status) and what the haptic
/// tools exchange with it (poses, feedback, events), and turns it into the
/// browser messages of docs/viewer.md. No HTTP here: the feed hands each
/// message to a callback, from its own thread.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "palpate/runtime/tool_geometry.hpp"

namespace palpate::viewer {

/// One message for the browsers.
struct Message {
  enum class Kind : std::uint8_t {
    kModel,    ///< a model's description and geometry: kept, replayed to every new page
    kSurface,  ///< a model's latest displacement: only the newest matters
    kTools,    ///< every tool's latest pose and feedback: only the newest matters
    kStatus,   ///< daemon status and the bridge's rates: only the newest matters
    kEvent,    ///< a tool event: every one is delivered, in order
    /// a model's surface stream ended (palpated stopped): replaces its last kSurface
    kSurfaceEnded,
  };
  Kind kind;
  std::string
      key;  ///< what a newer message of the same kind replaces (the model id for kModel/kSurface*)
  std::string text;    ///< JSON text frame (may be empty)
  std::string binary;  ///< binary frame sent after the text (may be empty)
};

struct FeedOptions {
  std::uint32_t domain_id = 0;
  std::string dds_config;           ///< as --dds-config: empty means CYCLONEDDS_URI, then loopback
  std::vector<ToolGeometry> tools;  ///< how to draw the tools, by id (unknown ids get the defaults)
  double tools_rate_hz = 60;        ///< at most this many tool messages per second
};

/// Reads palpated's topics in a thread of its own until destroyed.
class Feed {
 public:
  using Sink = std::function<void(Message)>;
  /// Joins the DDS domain (throws SystemError / InputError naming what failed)
  /// and starts the thread; @p sink is called from that thread.
  Feed(const FeedOptions& options, Sink sink);
  ~Feed();
  Feed(const Feed&) = delete;
  Feed& operator=(const Feed&) = delete;

  /// Where the DDS configuration came from, for the start-up line.
  const std::string& dds_origin() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace palpate::viewer
