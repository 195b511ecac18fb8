// Foxglove WebSocket protocol + HTTP on one port (view_server.hpp).
#include "reflex/view_node/view_server.hpp"

#include <nlohmann/json.hpp>
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <sys/stat.h>
#include <thread>

namespace reflex::view_node {
namespace {

using Server = websocketpp::server<websocketpp::config::asio>;
using nlohmann::json;
/// The Foxglove WebSocket subprotocols served, one protocol under two names: the protocol's own
/// (`foxglove.websocket.v1`) and the newer one clients of the Foxglove SDK offer (`foxglove.sdk.v1`).
constexpr std::array<const char*, 2> kSubprotocols{"foxglove.websocket.v1", "foxglove.sdk.v1"};

/// The first subprotocol the client offered that is served ("" if none): the client's order decides.
std::string chooseSubprotocol(const std::vector<std::string>& offered) {
  for (const std::string& p : offered)
    for (const char* served : kSubprotocols)
      if (p == served) return p;
  return "";
}

bool isRegularFile(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

bool readFile(const std::string& path, std::string& out) {
  if (!isRegularFile(path)) return false;
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  out = ss.str();
  return static_cast<bool>(in) || in.eof();
}

/// A request path that names one file of the web folder: letters, digits, '.', '_', '-', no leading '.'.
bool plainName(const std::string& name) {
  if (name.empty() || name.size() > 100 || name[0] == '.') return false;
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) return false;
  return true;
}

const char* contentType(const std::string& name) {
  auto ends = [&](const char* ext) {
    const std::string e(ext);
    return name.size() >= e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0;
  };
  if (ends(".html")) return "text/html; charset=utf-8";
  if (ends(".js") || ends(".mjs")) return "text/javascript; charset=utf-8";
  if (ends(".css")) return "text/css; charset=utf-8";
  if (ends(".json")) return "application/json";
  if (ends(".png")) return "image/png";
  if (ends(".svg")) return "image/svg+xml";
  return "application/octet-stream";
}

void putLE(std::string& out, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}

/// The first `n` bytes of a client's text, to quote it in a reply (a cut multi-byte character is
/// replaced when the reply is dumped, never thrown on).
std::string excerpt(const std::string& text, std::size_t n = 80) {
  return text.size() <= n ? text : text.substr(0, n) + "...";
}

/// `text` for a log line: control bytes as \xNN, so a client's quoted bytes cannot drive the terminal.
std::string printable(const std::string& text) {
  std::string out;
  for (const char ch : text) {
    const auto b = static_cast<unsigned char>(ch);
    if (b < 0x20 || b == 0x7F) {
      static const char* const kHex = "0123456789ABCDEF";
      out += std::string("\\x") + kHex[b >> 4] + kHex[b & 0xF];
    } else {
      out.push_back(ch);
    }
  }
  return out;
}

/// JSON text of a reply; invalid UTF-8 from a client's quoted bytes becomes U+FFFD.
std::string dumpReply(const json& j) { return j.dump(-1, ' ', false, json::error_handler_t::replace); }

/// One client's state, held only while it is connected (erased on close).
struct ClientState {
  std::map<std::uint32_t, std::size_t> subs;           ///< subscription id -> channel index
  std::string address;                                 ///< "127.0.0.1:45678": names the client in the log
  std::chrono::steady_clock::time_point window_start;  ///< start of the current one-second window
  std::size_t bad_in_window = 0;                       ///< bad messages in that window
  bool closing = false;                                ///< disconnected by us: nothing more queued or read
  bool full = false;  ///< a data frame was skipped, and the queue stayed above half the budget
  std::chrono::steady_clock::time_point full_since;  ///< since then
};

}  // namespace

struct ViewServer::Impl {
  ServerOptions options;
  std::vector<Channel> channels;
  std::unique_ptr<std::atomic<int>[]> channel_subscribers;  ///< per channel index: open subscriptions
  Server server;
  std::thread thread;
  bool started = false;
  ServerStats* stats = nullptr;
  std::string server_info, advertise;
  /// Per connection (I/O thread only).
  std::map<websocketpp::connection_hdl, ClientState, std::owner_less<websocketpp::connection_hdl>> clients;

  int channelIndex(std::uint32_t id) const {
    for (std::size_t i = 0; i < channels.size(); ++i)
      if (channels[i].id == id) return static_cast<int>(i);
    return -1;
  }

  /// Ends a client's connection and writes one line naming it and why. `drop_queue`: at once, with
  /// what is queued to it (it does not read, so a close frame behind the queue would never arrive);
  /// otherwise a close frame (policy violation) carrying `reason`, so a client that reads learns why.
  void disconnect(const Server::connection_ptr& con, ClientState& c, bool drop_queue, const std::string& reason) {
    if (c.closing) return;
    c.closing = true;
    stats->clients_disconnected++;
    std::fprintf(stderr, "reflex_view: client %s disconnected: %s\n", c.address.c_str(), printable(reason).c_str());
    websocketpp::lib::error_code ec;
    if (!drop_queue) con->close(websocketpp::close::status::policy_violation, excerpt(reason, 100), ec);
    if (drop_queue || ec) {
      // Posted: terminating runs the close handler, which erases `c` while the caller may still use it.
      websocketpp::lib::asio::post(server.get_io_service(), [con] { con->terminate(websocketpp::lib::error_code()); });
    }
  }

  /// True if `bytes` more fit the client's budget (kMaxBufferedBytes queued, all messages together).
  /// A data frame (`droppable`) that does not fit is skipped and counted: a newer scene follows. A
  /// reply that does not fit cannot be skipped without breaking the protocol: the client is
  /// disconnected, as is one whose data has not fitted for kMaxStall.
  bool fits(const Server::connection_ptr& con, ClientState& c, std::size_t bytes, bool droppable) {
    if (c.closing) return false;
    const std::size_t queued = con->get_buffered_amount();
    // A client that reads at all empties the counted queue now and then (websocketpp takes all of it
    // into each write); one that does not keeps it near the budget, small frames still fitting.
    if (queued < ViewServer::kMaxBufferedBytes / 2) c.full = false;
    if (queued + bytes <= ViewServer::kMaxBufferedBytes) return true;
    if (!droppable) {
      disconnect(con, c, true,
                 std::to_string(queued) + " bytes queued to it and a reply of " + std::to_string(bytes) +
                     " would pass its budget of " + std::to_string(ViewServer::kMaxBufferedBytes) +
                     " bytes (it does not read what it asks for)");
      return false;
    }
    stats->dropped++;
    const auto now = std::chrono::steady_clock::now();
    if (!c.full) {
      c.full = true;
      c.full_since = now;
    } else if (now - c.full_since > ViewServer::kMaxStall) {
      disconnect(con, c, true,
                 "its queue has stayed at the budget of " + std::to_string(ViewServer::kMaxBufferedBytes) +
                     " bytes for " + std::to_string(ViewServer::kMaxStall.count()) + " s (it does not read)");
    }
    return false;
  }

  /// Queues a reply (serverInfo, advertise, status) to one client within its budget (fits()).
  bool queueReply(websocketpp::connection_hdl hdl, ClientState& c, const std::string& text) {
    websocketpp::lib::error_code ec;
    Server::connection_ptr con = server.get_con_from_hdl(hdl, ec);
    if (ec || !con || !fits(con, c, text.size(), false)) return false;
    return !con->send(text, websocketpp::frame::opcode::text);
  }

  /// A `status` message (level 0 info, 1 warning, 2 error) to one client.
  void status(websocketpp::connection_hdl hdl, ClientState& c, int level, const std::string& message) {
    queueReply(hdl, c, dumpReply(json{{"op", "status"}, {"level", level}, {"message", message}}));
  }

  /// Counts a bad message; answers the first kMaxRepliesPerSecond of each second with a status error
  /// naming it, and disconnects a client past kMaxBadMessagesPerSecond (it ignores the answers).
  void badMessage(websocketpp::connection_hdl hdl, ClientState& c, const std::string& message) {
    stats->bad_client_messages++;
    const auto now = std::chrono::steady_clock::now();
    if (now - c.window_start >= std::chrono::seconds(1)) {
      c.window_start = now;
      c.bad_in_window = 0;
    }
    if (++c.bad_in_window > ViewServer::kMaxBadMessagesPerSecond) {
      websocketpp::lib::error_code ec;
      Server::connection_ptr con = server.get_con_from_hdl(hdl, ec);
      if (!ec && con)
        disconnect(con, c, false,
                   "more than " + std::to_string(ViewServer::kMaxBadMessagesPerSecond) +
                       " bad messages in one second (last: " + excerpt(message, 60) + ")");
      return;
    }
    if (c.bad_in_window > ViewServer::kMaxRepliesPerSecond) {
      stats->replies_not_sent++;
      return;
    }
    status(hdl, c, 2, message);
  }

  void onMessage(websocketpp::connection_hdl hdl, Server::message_ptr msg) {
    auto it = clients.find(hdl);
    if (it == clients.end() || it->second.closing) return;
    ClientState& c = it->second;
    if (msg->get_opcode() != websocketpp::frame::opcode::text) {
      badMessage(hdl, c, "binary client messages are not supported (no clientPublish / services capability)");
      return;
    }
    json m = json::parse(msg->get_payload(), nullptr, false);
    if (m.is_discarded() || !m.is_object() || !m.contains("op") || !m["op"].is_string()) {
      badMessage(hdl, c, "client message is not a JSON object with an \"op\": '" + excerpt(msg->get_payload()) + "'");
      return;
    }
    const std::string op = m["op"].get<std::string>();
    auto& subs = c.subs;
    if (op == "subscribe") {
      if (!m.contains("subscriptions") || !m["subscriptions"].is_array()) {
        badMessage(hdl, c, "subscribe without a \"subscriptions\" array");
        return;
      }
      for (const json& s : m["subscriptions"]) {
        if (c.closing) return;
        if (!s.is_object() || !s.contains("id") || !s["id"].is_number_unsigned() || !s.contains("channelId") ||
            !s["channelId"].is_number_unsigned() || s["id"].get<std::uint64_t>() > 0xFFFFFFFFull ||
            s["channelId"].get<std::uint64_t>() > 0xFFFFFFFFull) {
          badMessage(
              hdl, c,
              "subscribe: bad subscription " + excerpt(dumpReply(s)) + " (needs unsigned 32-bit id and channelId)");
          continue;
        }
        const auto id = s["id"].get<std::uint32_t>();
        const int ch = channelIndex(s["channelId"].get<std::uint32_t>());
        if (ch < 0) {
          badMessage(hdl, c, "subscribe: unknown channel id " + s["channelId"].dump());
        } else if (subs.count(id)) {
          badMessage(hdl, c, "subscribe: subscription id " + std::to_string(id) + " is already in use");
        } else if (subs.size() >= ViewServer::kMaxSubscriptionsPerClient) {
          badMessage(hdl, c,
                     "subscribe: subscription id " + std::to_string(id) + " refused: at most " +
                         std::to_string(ViewServer::kMaxSubscriptionsPerClient) +
                         " subscriptions per client (unsubscribe one first)");
        } else {
          subs[id] = static_cast<std::size_t>(ch);
          channel_subscribers[static_cast<std::size_t>(ch)]++;
          stats->subscriptions++;
        }
      }
    } else if (op == "unsubscribe") {
      if (!m.contains("subscriptionIds") || !m["subscriptionIds"].is_array()) {
        badMessage(hdl, c, "unsubscribe without a \"subscriptionIds\" array");
        return;
      }
      for (const json& s : m["subscriptionIds"]) {
        if (c.closing) return;
        const bool ok = s.is_number_unsigned() && s.get<std::uint64_t>() <= 0xFFFFFFFFull;
        auto sub = ok ? subs.find(s.get<std::uint32_t>()) : subs.end();
        if (sub == subs.end()) {
          badMessage(hdl, c, "unsubscribe: unknown subscription id " + excerpt(dumpReply(s)));
          continue;
        }
        channel_subscribers[sub->second]--;
        subs.erase(sub);
      }
    } else {
      badMessage(hdl, c, "unsupported op '" + excerpt(op) + "' (this server offers subscribe and unsubscribe only)");
    }
  }

  /// The handlers run on the one I/O thread, and an exception out of one would end it for every
  /// client: whatever a client's message makes throw disconnects that client, naming the exception.
  void onMessageGuarded(websocketpp::connection_hdl hdl, Server::message_ptr msg) {
    try {
      onMessage(hdl, msg);
    } catch (const std::exception& e) {
      stats->bad_client_messages++;
      auto it = clients.find(hdl);
      websocketpp::lib::error_code ec;
      Server::connection_ptr con = server.get_con_from_hdl(hdl, ec);
      if (it != clients.end() && !ec && con)
        disconnect(con, it->second, true, std::string("its message could not be handled: ") + e.what());
    }
  }

  void onClose(websocketpp::connection_hdl hdl) {
    auto it = clients.find(hdl);
    if (it == clients.end()) return;
    websocketpp::lib::error_code ec;
    Server::connection_ptr con = server.get_con_from_hdl(hdl, ec);
    if (!ec && con && !it->second.closing &&
        con->get_local_close_code() == websocketpp::close::status::message_too_big) {
      // websocketpp refused the message itself (set_max_message_size): say so like our own limits.
      stats->clients_disconnected++;
      std::fprintf(stderr, "reflex_view: client %s disconnected: a message of more than %zu bytes\n",
                   it->second.address.c_str(), ViewServer::kMaxClientMessageBytes);
    }
    for (const auto& [id, ch] : it->second.subs) channel_subscribers[ch]--;
    clients.erase(it);
    stats->open--;
  }

  void onHttp(websocketpp::connection_hdl hdl) {
    Server::connection_ptr con = server.get_con_from_hdl(hdl);
    stats->http_requests++;
    const std::string method = con->get_request().get_method();
    std::string resource = con->get_resource();
    const auto q = resource.find_first_of("?#");
    if (q != std::string::npos) resource.resize(q);
    std::string body, name;
    bool found = false;
    if (method == "GET" || method == "HEAD") {
      if (resource == "/" || resource == "/index.html") {
        name = "index.html";
        found = readFile(options.web_dir + "/index.html", body);
      } else if (resource == "/three/three.module.js" || resource == "/three/three.core.js") {
        name = resource.substr(7);
        found = readFile(options.three_dir + "/" + name, body);
      } else if (resource.size() > 1 && plainName(resource.substr(1))) {
        name = resource.substr(1);
        found = readFile(options.web_dir + "/" + name, body);
      }
    }
    if (!found) {
      stats->http_not_found++;
      con->set_status(method == "GET" || method == "HEAD" ? websocketpp::http::status_code::not_found
                                                          : websocketpp::http::status_code::method_not_allowed);
      con->replace_header("Content-Type", "text/plain; charset=utf-8");
      con->set_body("reflex_view: " + method + " " + resource + ": not found\n");
      return;
    }
    con->set_status(websocketpp::http::status_code::ok);
    con->replace_header("Content-Type", contentType(name));
    con->replace_header("Cache-Control", "no-cache");
    con->set_body(method == "HEAD" ? std::string() : body);
  }
};

ViewServer::ViewServer(const ServerOptions& options, std::vector<Channel> channels) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  m.channels = std::move(channels);
  m.stats = &stats_;
  m.channel_subscribers = std::make_unique<std::atomic<int>[]>(m.channels.size());
  for (std::size_t i = 0; i < m.channels.size(); ++i) m.channel_subscribers[i] = 0;

  if (options.port < 0 || options.port > 65535)
    throw ViewError("--port " + std::to_string(options.port) + " is outside 0..65535");
  if (!isRegularFile(options.web_dir + "/index.html"))
    throw ViewError("--web folder '" + options.web_dir + "' has no index.html (the page of modules/view/web)");
  if (!isRegularFile(options.three_dir + "/three.module.js") || !isRegularFile(options.three_dir + "/three.core.js"))
    throw ViewError("three.js not found in '" + options.three_dir +
                    "' (three.module.js, three.core.js): run `npm ci` in bringup/web, or give --three DIR");
  websocketpp::lib::asio::error_code addr_ec;
  const auto address = websocketpp::lib::asio::ip::make_address(options.bind, addr_ec);
  if (addr_ec) throw ViewError("--bind '" + options.bind + "' is not an IP address (" + addr_ec.message() + ")");
  websocketpp::lib::error_code ec;

  m.server.clear_access_channels(websocketpp::log::alevel::all);
  m.server.clear_error_channels(websocketpp::log::elevel::all);
  m.server.init_asio(ec);
  if (ec) throw ViewError("cannot start the WebSocket server: " + ec.message());
  // Inbound limits (view_server.hpp, "Limits per client"): websocketpp's defaults are 32 MB.
  m.server.set_max_message_size(kMaxClientMessageBytes);
  m.server.set_max_http_body_size(kMaxClientMessageBytes);
  m.server.set_close_handshake_timeout(1000);
  m.server.set_reuse_addr(true);
  const websocketpp::lib::asio::ip::tcp::endpoint endpoint(address, static_cast<unsigned short>(options.port));
  const std::string where =
      (address.is_v6() ? "[" + options.bind + "]" : options.bind) + ":" + std::to_string(options.port);
  {
    // websocketpp reports every bind failure as "Underlying Transport Error": bind once here with the
    // same options to name the cause (address in use, not an address of this machine, permission).
    websocketpp::lib::asio::io_service probe_io;
    websocketpp::lib::asio::ip::tcp::acceptor probe(probe_io);
    probe.open(endpoint.protocol(), addr_ec);
    if (!addr_ec) probe.set_option(websocketpp::lib::asio::socket_base::reuse_address(true), addr_ec);
    if (!addr_ec) probe.bind(endpoint, addr_ec);
    if (addr_ec) throw ViewError("cannot listen on " + where + ": " + addr_ec.message() + " (--bind / --port)");
  }
  m.server.listen(endpoint, ec);
  if (ec) throw ViewError("cannot listen on " + where + ": " + ec.message() + " (--bind / --port)");
  const auto local = m.server.get_local_endpoint(addr_ec);
  if (addr_ec) throw ViewError("cannot read the listening port of " + where + ": " + addr_ec.message());
  port_ = local.port();

  json advertised = json::array();
  for (const Channel& c : m.channels)
    advertised.push_back(json{{"id", c.id},
                              {"topic", c.topic},
                              {"encoding", "json"},
                              {"schemaName", c.schema_name},
                              {"schema", c.schema},
                              {"schemaEncoding", "jsonschema"}});
  m.advertise = json{{"op", "advertise"}, {"channels", std::move(advertised)}}.dump();
  m.server_info = json{{"op", "serverInfo"},
                       {"name", options.name},
                       {"capabilities", json::array()},
                       {"supportedEncodings", json::array()},
                       {"metadata", {{"robot", options.metadata_robot}}},
                       {"sessionId", std::to_string(std::chrono::system_clock::now().time_since_epoch().count())}}
                      .dump();

  m.server.set_validate_handler([&m](websocketpp::connection_hdl hdl) {
    Server::connection_ptr con = m.server.get_con_from_hdl(hdl);
    if (m.clients.size() >= kMaxClients) {
      m.stats->clients_refused++;
      con->set_status(websocketpp::http::status_code::service_unavailable);
      con->set_body("reflex_view serves at most " + std::to_string(kMaxClients) + " WebSocket clients at once\n");
      return false;
    }
    const std::string chosen = chooseSubprotocol(con->get_requested_subprotocols());
    if (!chosen.empty()) {
      websocketpp::lib::error_code ec;
      con->select_subprotocol(chosen, ec);
      return !ec;
    }
    con->set_status(websocketpp::http::status_code::bad_request);
    con->set_body(std::string("reflex_view speaks the WebSocket subprotocols ") + kSubprotocols[0] + " and " +
                  kSubprotocols[1] + " only\n");
    return false;
  });
  m.server.set_open_handler([&m](websocketpp::connection_hdl hdl) {
    ClientState& c = m.clients[hdl];
    websocketpp::lib::error_code ec;
    Server::connection_ptr con = m.server.get_con_from_hdl(hdl, ec);
    if (!ec && con) c.address = con->get_remote_endpoint();
    m.stats->connections++;
    m.stats->open++;
    m.queueReply(hdl, c, m.server_info);
    m.queueReply(hdl, c, m.advertise);
  });
  m.server.set_close_handler([&m](websocketpp::connection_hdl hdl) { m.onClose(hdl); });
  m.server.set_fail_handler([](websocketpp::connection_hdl) {});
  m.server.set_message_handler(
      [&m](websocketpp::connection_hdl hdl, Server::message_ptr msg) { m.onMessageGuarded(hdl, msg); });
  m.server.set_http_handler([&m](websocketpp::connection_hdl hdl) { m.onHttp(hdl); });
}

ViewServer::~ViewServer() { stop(); }

std::string ViewServer::url() const {
  const bool v6 = impl_->options.bind.find(':') != std::string::npos;
  return "http://" + (v6 ? "[" + impl_->options.bind + "]" : impl_->options.bind) + ":" + std::to_string(port_);
}

void ViewServer::start() {
  Impl& m = *impl_;
  if (m.started) return;
  websocketpp::lib::error_code ec;
  m.server.start_accept(ec);
  if (ec) throw ViewError("cannot accept connections: " + ec.message());
  m.started = true;
  m.thread = std::thread([&m] {
    try {
      m.server.run();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "reflex_view: server stopped: %s\n", e.what());
    }
  });
}

void ViewServer::stop() noexcept {
  Impl& m = *impl_;
  if (!m.started) return;
  m.started = false;
  try {
    websocketpp::lib::asio::post(m.server.get_io_service(), [&m] {
      websocketpp::lib::error_code ec;
      m.server.stop_listening(ec);
      for (auto& [hdl, c] : m.clients)
        m.server.close(hdl, websocketpp::close::status::going_away, "reflex_view stopping", ec);
    });
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(500);
    while (stats_.open.load() > 0 && std::chrono::steady_clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    m.server.stop();
  } catch (...) {
  }
  if (m.thread.joinable()) m.thread.join();
}

void ViewServer::publish(std::uint32_t channel, std::uint64_t stamp_ns, std::shared_ptr<const std::string> payload) {
  Impl& m = *impl_;
  const int ch = m.channelIndex(channel);
  if (ch < 0 || !payload || !m.started) return;
  websocketpp::lib::asio::post(m.server.get_io_service(), [&m, this, ch, stamp_ns, payload] {
    for (auto& [hdl, c] : m.clients) {
      websocketpp::lib::error_code hdl_ec;
      Server::connection_ptr con = m.server.get_con_from_hdl(hdl, hdl_ec);
      if (hdl_ec || !con) continue;
      for (const auto& [id, sub_ch] : c.subs) {
        if (sub_ch != static_cast<std::size_t>(ch)) continue;
        if (!m.fits(con, c, 13 + payload->size(), true)) continue;  // checked before the frame is built
        std::string frame;
        frame.reserve(13 + payload->size());
        frame.push_back(static_cast<char>(0x01));  // messageData
        putLE(frame, id, 4);
        putLE(frame, stamp_ns, 8);
        frame += *payload;
        if (!con->send(frame, websocketpp::frame::opcode::binary)) stats_.messages_sent++;
      }
    }
  });
}

bool ViewServer::subscribed(std::uint32_t channel) const {
  const int ch = impl_->channelIndex(channel);
  return ch >= 0 && impl_->channel_subscribers[static_cast<std::size_t>(ch)].load() > 0;
}

}  // namespace reflex::view_node
