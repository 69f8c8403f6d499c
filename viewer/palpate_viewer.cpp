// palpate-viewer: a bridge from palpated's DDS topics to a web page. It
// serves the page (viewer/web) and three.js over HTTP on localhost, and
// pushes the organ, its deformation, the tools and the rates to every open
// page over a WebSocket (/ws). docs/viewer.md has the protocol and options.
//
// Threads: the feed's DDS thread builds the messages; this (main) thread
// runs Boost.Asio, owns every connection and the hub, and is the only one
// that touches them (messages cross over by net::post).

#include <fcntl.h>
#include <sched.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <boost/asio.hpp>
#include <boost/beast.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include "feed.hpp"
#include "palpate/core/error.hpp"
#include "palpate/core/suggest.hpp"
#include "palpate/core/version.hpp"
#include "palpate/daemon/daemon_config.hpp"

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;
namespace fs = std::filesystem;

namespace palpate::viewer {
namespace {

using MessagePtr = std::shared_ptr<const Message>;

/// Boost 1.74's Beast speaks boost::string_view.
std::string_view std_view(beast::string_view s) { return {s.data(), s.size()}; }
beast::string_view beast_view(std::string_view s) { return {s.data(), s.size()}; }

class WebSocketSession;

/// The latest state of everything, replayed to each page that connects, and
/// the open pages to which each new message goes. Main thread only.
class Hub {
 public:
  void join(WebSocketSession* session);
  void leave(WebSocketSession* session) { sessions_.erase(session); }
  void publish(const MessagePtr& message);

 private:
  std::map<std::string, MessagePtr> models_;  // by model id
  std::map<std::string, MessagePtr> latest_;  // surfaces (or their end) by model, tools, status
  std::set<WebSocketSession*> sessions_;
};

/// The key under which a newer message replaces an older one still waiting
/// to be sent; empty for messages that must all be delivered in order.
std::string coalescing_key(const Message& m) {
  switch (m.kind) {
    case Message::Kind::kSurface:
    case Message::Kind::kSurfaceEnded:  // the end of a stream replaces its last sample
      return "surface:" + m.key;
    case Message::Kind::kTools:
      return "tools";
    case Message::Kind::kStatus:
      return "status";
    case Message::Kind::kModel:
    case Message::Kind::kEvent:
      return {};
  }
  return {};
}

/// One page. Messages that must arrive (models, events) queue in order and
/// go first; of the others (surface, tools, status) only the newest waits, so
/// a slow page skips frames instead of falling behind.
class WebSocketSession : public std::enable_shared_from_this<WebSocketSession> {
 public:
  WebSocketSession(tcp::socket socket, Hub& hub) : ws_(std::move(socket)), hub_(hub) {}
  ~WebSocketSession() { hub_.leave(this); }

  void start(http::request<http::string_body> request) {
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    ws_.set_option(websocket::stream_base::decorator([](websocket::response_type& r) {
      r.set(http::field::server, "palpate-viewer " PALPATE_VERSION);
    }));
    ws_.async_accept(request, [self = shared_from_this()](beast::error_code ec) {
      if (ec) return;
      self->hub_.join(self.get());
      self->read();
    });
  }

  void send(const MessagePtr& message) {
    if (closed_) return;
    if (const std::string key = coalescing_key(*message); !key.empty()) {
      pending_[key] = message;
    } else {
      // A page that lets a thousand models and events pile up is gone.
      if (ordered_.size() >= kMaxOrdered) return close();
      ordered_.push_back(message);
    }
    write_next();
  }

 private:
  static constexpr std::size_t kMaxOrdered = 1024;

  void read() {
    ws_.async_read(incoming_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) return self->close();
      self->incoming_.clear();  // the page has nothing to say yet; control frames are handled
      self->read();
    });
  }

  void write_next() {
    if (writing_ || closed_) return;
    if (!current_) {
      if (!ordered_.empty()) {
        current_ = ordered_.front();
        ordered_.pop_front();
      } else if (!pending_.empty()) {
        current_ = pending_.begin()->second;
        pending_.erase(pending_.begin());
      } else {
        return;
      }
      binary_stage_ = current_->text.empty();
    }
    writing_ = true;
    const std::string& frame = binary_stage_ ? current_->binary : current_->text;
    ws_.binary(binary_stage_);
    ws_.async_write(net::buffer(frame),
                    [self = shared_from_this()](beast::error_code ec, std::size_t) {
                      self->writing_ = false;
                      if (ec) return self->close();
                      if (!self->binary_stage_ && !self->current_->binary.empty())
                        self->binary_stage_ = true;
                      else
                        self->current_.reset();
                      self->write_next();
                    });
  }

  void close() {
    if (closed_) return;
    closed_ = true;
    hub_.leave(this);
    beast::error_code ignored;
    beast::get_lowest_layer(ws_).socket().shutdown(tcp::socket::shutdown_both, ignored);
  }

  websocket::stream<beast::tcp_stream> ws_;
  Hub& hub_;
  beast::flat_buffer incoming_;
  std::deque<MessagePtr> ordered_;
  std::map<std::string, MessagePtr> pending_;
  MessagePtr current_;
  bool binary_stage_ = false, writing_ = false, closed_ = false;
};

void Hub::join(WebSocketSession* session) {
  sessions_.insert(session);
  for (const auto& [id, model] : models_) session->send(model);
  for (const auto& [key, message] : latest_) session->send(message);
}

void Hub::publish(const MessagePtr& message) {
  if (message->kind == Message::Kind::kModel) {
    // A model served anew with other geometry (palpated restarted on another
    // file): its last displacements no longer fit. A surface that came
    // before the model's first description is kept.
    auto& known = models_[message->key];
    if (known && known->binary != message->binary) latest_.erase("surface:" + message->key);
    known = message;
  } else if (const std::string key = coalescing_key(*message); !key.empty()) {
    latest_[key] = message;
  }
  // send() may close a session, which leaves the set: iterate over a copy.
  const std::vector<WebSocketSession*> targets(sessions_.begin(), sessions_.end());
  for (WebSocketSession* s : targets)
    if (sessions_.count(s)) s->send(message);
}

/// Where the page's files come from.
struct WebFiles {
  fs::path root;          ///< index.html, viewer.js, ...
  fs::path node_modules;  ///< three/ (served under /vendor/three/)
};

std::string_view content_type(const fs::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  return "application/octet-stream";
}

/// The file a GET target names, or empty when it names none we serve:
/// only [A-Za-z0-9._/-], no "..", under the web root or three.js.
fs::path resolve_target(const WebFiles& files, std::string_view target) {
  target = target.substr(0, target.find_first_of("?#"));
  if (target.empty() || target.front() != '/') return {};
  for (const char c : target)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '/' ||
          c == '-'))
      return {};
  if (target.find("..") != std::string_view::npos) return {};
  if (target == "/") return files.root / "index.html";
  constexpr std::string_view kVendor = "/vendor/three/";
  if (target.substr(0, kVendor.size()) == kVendor)
    return files.node_modules / "three" / fs::path(target.substr(kVendor.size()));
  return files.root / fs::path(target.substr(1));
}

/// Origin check for the WebSocket: only pages served from this machine
/// (or a client that sends no Origin, like a test tool) may connect.
bool local_origin(std::string_view origin) {
  if (origin.empty()) return true;
  for (const std::string_view host : {"http://127.0.0.1", "http://localhost", "http://[::1]"})
    if (origin.substr(0, host.size()) == host &&
        (origin.size() == host.size() || origin[host.size()] == ':'))
      return true;
  return false;
}

/// One HTTP connection: static files, or the upgrade to /ws.
class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket socket, Hub& hub, const WebFiles& files)
      : stream_(std::move(socket)), hub_(hub), files_(files) {}

  void read() {
    parser_.emplace();
    parser_->body_limit(16 * 1024);
    stream_.expires_after(std::chrono::seconds(30));
    http::async_read(stream_, buffer_, *parser_,
                     [self = shared_from_this()](beast::error_code ec, std::size_t) {
                       if (ec) return;  // closed, timed out or garbage: drop the connection
                       self->handle(self->parser_->release());
                     });
  }

 private:
  void handle(http::request<http::string_body> request) {
    if (websocket::is_upgrade(request)) {
      if (request.target() != "/ws" || !local_origin(std_view(request[http::field::origin])))
        return reply_error(request, http::status::forbidden,
                           "WebSocket: only /ws, from this host\n");
      stream_.expires_never();
      std::make_shared<WebSocketSession>(stream_.release_socket(), hub_)->start(std::move(request));
      return;
    }
    if (request.method() != http::verb::get && request.method() != http::verb::head)
      return reply_error(request, http::status::method_not_allowed, "GET or HEAD only\n");
    const fs::path file = resolve_target(files_, std_view(request.target()));
    beast::error_code ec;
    http::file_body::value_type body;
    if (!file.empty() && fs::is_regular_file(file))
      body.open(file.c_str(), beast::file_mode::scan, ec);
    if (file.empty() || !fs::is_regular_file(file) || ec)
      return reply_error(request, http::status::not_found, "not found\n");
    const auto size = body.size();
    const std::string type(content_type(file));
    if (request.method() == http::verb::head) {
      http::response<http::empty_body> response{http::status::ok, request.version()};
      decorate(response, type, request.keep_alive());
      response.content_length(size);
      return write(std::move(response));
    }
    http::response<http::file_body> response{std::piecewise_construct,
                                             std::make_tuple(std::move(body)),
                                             std::make_tuple(http::status::ok, request.version())};
    decorate(response, type, request.keep_alive());
    response.content_length(size);
    write(std::move(response));
  }

  template <typename Response>
  static void decorate(Response& response, std::string_view type, bool keep_alive) {
    response.set(http::field::server, "palpate-viewer " PALPATE_VERSION);
    response.set(http::field::content_type, beast_view(type));
    response.set(http::field::cache_control, "no-cache");
    response.set("X-Content-Type-Options", "nosniff");
    response.keep_alive(keep_alive);
  }

  void reply_error(const http::request<http::string_body>& request, http::status status,
                   std::string text) {
    http::response<http::string_body> response{status, request.version()};
    decorate(response, "text/plain; charset=utf-8", request.keep_alive());
    response.body() = std::move(text);
    response.prepare_payload();
    write(std::move(response));
  }

  template <typename Response>
  void write(Response&& response) {
    auto owned = std::make_shared<std::decay_t<Response>>(std::forward<Response>(response));
    http::async_write(stream_, *owned,
                      [self = shared_from_this(), owned](beast::error_code ec, std::size_t) {
                        if (ec || !owned->keep_alive()) {
                          beast::error_code ignored;
                          self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
                          return;
                        }
                        self->read();
                      });
  }

  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  Hub& hub_;
  const WebFiles& files_;
};

void accept(tcp::acceptor& acceptor, Hub& hub, const WebFiles& files) {
  acceptor.async_accept([&](beast::error_code ec, tcp::socket socket) {
    if (ec == net::error::operation_aborted) return;
    if (!ec) std::make_shared<HttpSession>(std::move(socket), hub, files)->read();
    accept(acceptor, hub, files);
  });
}

tcp::endpoint parse_listen(const std::string& text) {
  const auto colon = text.rfind(':');
  if (colon == std::string::npos)
    throw InputError("--listen " + text + ": expected ADDRESS:PORT, e.g. 127.0.0.1:8080");
  beast::error_code ec;
  std::string host = text.substr(0, colon);
  if (host.size() > 1 && host.front() == '[' && host.back() == ']')
    host = host.substr(1, host.size() - 2);
  const auto address = net::ip::make_address(host, ec);
  int port = -1;
  try {
    std::size_t used = 0;
    port = std::stoi(text.substr(colon + 1), &used);
    if (used != text.size() - colon - 1) port = -1;
  } catch (const std::exception&) {
  }
  if (ec || port < 0 || port > 65535)
    throw InputError("--listen " + text +
                     ": expected an IP address and a port 0-65535, e.g. 127.0.0.1:8080");
  return {address, static_cast<unsigned short>(port)};
}

/// Moves this thread (and the threads it starts later: the DDS ones) into
/// the network namespace @p path; sockets already open stay where they were.
void join_network_namespace(const std::string& path) {
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    throw InputError("--dds-netns " + path + ": " + std::strerror(errno) +
                     " (expected a network namespace file such as /proc/PID/ns/net)");
  const int rc = setns(fd, CLONE_NEWNET);
  const int error = errno;
  close(fd);
  if (rc != 0)
    throw SystemError("--dds-netns " + path + ": cannot join this network namespace: " +
                      std::strerror(error) + (error == EPERM ? " (needs root)" : ""));
}

int run(int argc, char** argv) {
  CLI::App app{
      "palpate-viewer: shows palpated's organs, their deformation and the tools in a web page"};
  app.set_version_flag("--version", "palpate-viewer " PALPATE_VERSION);
  std::string listen = "127.0.0.1:8080";
  std::string config_file, netns;
  WebFiles files{PALPATE_VIEWER_WEB_ROOT, PALPATE_VIEWER_NODE_MODULES};
  std::string web_root = files.root.string(), node_modules = files.node_modules.string();
  FeedOptions feed_options;
  app.add_option("--listen", listen, "HTTP address and port (default 127.0.0.1:8080)");
  app.add_option("--web-root", web_root,
                 "the page's files (default: viewer/web of the source tree)");
  app.add_option("--node-modules", node_modules,
                 "where npm installed three.js (default: viewer/node_modules of the source tree)");
  app.add_option("--domain", feed_options.domain_id, "DDS domain id");
  app.add_option(
      "--dds-config", feed_options.dds_config,
      "Cyclone DDS configuration: XML file, file:// URI or XML fragment (default: loopback only)");
  app.add_option(
      "-c,--config", config_file,
      "palpated's configuration, for the tools' geometry ([[tools]]); other keys ignored");
  app.add_option("--tools-hz", feed_options.tools_rate_hz, "tool updates sent to pages, per second")
      ->check(CLI::Range(1.0, 1000.0));
  app.add_option(
      "--dds-netns", netns,
      "open the HTTP port here, then join this network namespace (e.g. /proc/PID/ns/net) "
      "for DDS");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "palpate-viewer: error: %s%s (see --help)\n", e.what(),
                 palpate::flag_suggestions(std::vector<std::string>(argv + 1, argv + argc),
                                           palpate::long_flag_names(app))
                     .c_str());
    return static_cast<int>(ExitCode::kUsage);
  }
  files = {web_root, node_modules};
  if (!fs::is_regular_file(files.root / "index.html"))
    throw InputError("--web-root " + web_root + ": no index.html there (expected viewer/web)");
  if (!fs::is_regular_file(files.node_modules / "three/build/three.module.js"))
    throw InputError("--node-modules " + node_modules +
                     ": three.js is not installed there (three/build/three.module.js); run "
                     "scripts/install-deps.sh, which runs npm ci in viewer/");
  if (!config_file.empty()) feed_options.tools = read_daemon_config(config_file).tools;

  Hub hub;  // outlives the io_context, whose pending handlers hold sessions
  net::io_context io(1);
  const tcp::endpoint endpoint = parse_listen(listen);
  tcp::acceptor acceptor(io);
  beast::error_code ec;
  acceptor.open(endpoint.protocol(), ec);
  if (!ec) acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) acceptor.bind(endpoint, ec);
  if (!ec) acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) throw SystemError("--listen " + listen + ": " + ec.message());
  const tcp::endpoint bound = acceptor.local_endpoint();
  if (!netns.empty()) join_network_namespace(netns);

  Feed feed(feed_options, [&io, &hub](Message m) {
    net::post(io, [&hub, message = std::make_shared<const Message>(std::move(m))] {
      hub.publish(message);
    });
  });
  accept(acceptor, hub, files);
  net::signal_set signals(io, SIGINT, SIGTERM);
  signals.async_wait([&](beast::error_code, int) {
    acceptor.close();
    io.stop();
  });
  std::printf("palpate-viewer: http://%s:%u/ (domain %u, DDS configuration: %s)\n",
              bound.address().to_string().c_str(), bound.port(), feed_options.domain_id,
              feed.dds_origin().c_str());
  std::fflush(stdout);
  io.run();
  return 0;
}

}  // namespace
}  // namespace palpate::viewer

int main(int argc, char** argv) {
  try {
    return palpate::viewer::run(argc, argv);
  } catch (...) {
    return palpate::report_current_exception("palpate-viewer");
  }
}
