// The live view's server: one TCP port that speaks the Foxglove WebSocket protocol
// (`foxglove.websocket.v1`, https://github.com/foxglove/ws-protocol docs/spec.md) to any WebSocket
// client that offers that subprotocol or its newer name `foxglove.sdk.v1` (the handshake answers with
// the first of the two the client offered; neither: HTTP 400), and plain HTTP GET of the bundled web
// page to anything else.
// websocketpp (Debian) on Boost.Asio, one I/O thread; no DDS here (ViewNode feeds it).
//
// Protocol subset served: on connect `serverInfo` (no capabilities: clients may not publish, call
// services or set parameters) and `advertise` of every channel (encoding "json", schemaEncoding
// "jsonschema"); the client's `subscribe` / `unsubscribe`; binary `messageData` frames (opcode 0x01,
// uint32 subscription id, uint64 timestamp [ns], payload; little-endian). A bad client message (not
// JSON, unknown op, unknown channel, a subscription id already in use or unknown, a subscription past
// kMaxSubscriptionsPerClient, any binary frame) is counted, changes nothing, and gets a `status`
// message of level error naming it (the first kMaxRepliesPerSecond of each second; later ones only
// counted in `replies_not_sent`).
//
// Limits per client, so that no client, however it behaves, grows the process (a client's state
// lives only while it is connected):
//   - Every byte queued to a client (messageData, status, serverInfo, advertise) counts against one
//     budget, kMaxBufferedBytes. A data frame that does not fit is skipped (`dropped`: a viewer that
//     reads slower than the scene is produced catches up with a newer one); when the queue has not
//     gone below half the budget for kMaxStall since a frame was skipped, the client is disconnected
//     at once, its queue dropped (a frozen tab: the page reconnects by itself when it runs again). A reply that does not fit disconnects the client the
//     same way: it asks and never reads. Memory held for a client is at most twice the budget (the
//     batch being written and the queue behind it).
//   - More than kMaxBadMessagesPerSecond bad messages within one second: disconnected (close 1008,
//     the reason in the close frame).
//   - A message of more than kMaxClientMessageBytes: disconnected by websocketpp (close 1009).
//   - At most kMaxClients WebSocket clients at once; the next gets HTTP 503.
// Every disconnect writes one line on stderr naming the client's address and why, and is counted in
// `clients_disconnected`.
//
// HTTP: "/" serves index.html of the web folder; "/<name>" a file of the web folder (names of
// letters, digits, '.', '_', '-' only; no sub-folders); "/three/three.module.js" and
// "/three/three.core.js" three.js from the npm package folder (bringup/web/node_modules/three/build).
// Anything else: 404. Only GET/HEAD.
#pragma once

#include "reflex/common/error.hpp"
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace reflex::view_node {

/// Set-up errors of the server (bad address, port in use, missing web folder): the message names the
/// value and the option.
class ViewError : public reflex::Error {
 public:
  using reflex::Error::Error;
};

struct ServerOptions {
  std::string bind = "127.0.0.1";  ///< --bind: IPv4/IPv6 address to listen on (localhost unless told)
  int port = 8765;                 ///< --port: 0..65535 (0: the system picks one; see ViewServer::port())
  std::string web_dir;             ///< folder with index.html and the page's scripts
  std::string three_dir;           ///< folder with three.module.js and three.core.js
  std::string name = "reflex_view";
  std::string metadata_robot;  ///< serverInfo.metadata.robot
};

/// A channel advertised to every client.
struct Channel {
  std::uint32_t id = 0;
  std::string topic;
  std::string schema_name;
  std::string schema;  ///< JSON schema text
};

struct ServerStats {
  std::atomic<std::uint64_t> connections{0};    ///< WebSocket connections opened, since start
  std::atomic<std::uint64_t> open{0};           ///< open now
  std::atomic<std::uint64_t> http_requests{0};  ///< plain HTTP requests served (any status)
  std::atomic<std::uint64_t> http_not_found{0};
  std::atomic<std::uint64_t> messages_sent{0};  ///< messageData frames sent
  std::atomic<std::uint64_t> dropped{0};        ///< messageData frames not sent to a slow client
  std::atomic<std::uint64_t> bad_client_messages{0};
  std::atomic<std::uint64_t> replies_not_sent{0};      ///< bad messages past kMaxRepliesPerSecond: not answered
  std::atomic<std::uint64_t> clients_disconnected{0};  ///< clients over a limit, disconnected by the server
  std::atomic<std::uint64_t> clients_refused{0};       ///< handshakes refused past kMaxClients
  std::atomic<std::uint64_t> subscriptions{0};         ///< subscribe requests accepted, since start
};

class ViewServer {
 public:
  /// Bytes queued to one client, all messages together: ~3 s of scene at 30 Hz (older is useless to a viewer).
  static constexpr std::size_t kMaxBufferedBytes = 2u << 20;
  /// How long a client's data frames may be skipped in a row before it is disconnected.
  static constexpr std::chrono::seconds kMaxStall{10};
  /// Subscriptions one client may hold: the page and Foxglove take one per channel (3).
  static constexpr std::size_t kMaxSubscriptionsPerClient = 64;
  /// Bad messages answered with a status per client and second; more are counted only.
  static constexpr std::size_t kMaxRepliesPerSecond = 10;
  /// Bad messages per client and second past which it is disconnected.
  static constexpr std::size_t kMaxBadMessagesPerSecond = 100;
  /// Largest message a client may send [bytes] (a subscribe of 64 subscriptions is ~2 kB); also the
  /// largest HTTP request body.
  static constexpr std::size_t kMaxClientMessageBytes = 64u << 10;
  /// WebSocket clients served at once.
  static constexpr std::size_t kMaxClients = 32;

  /// Checks the folders and the address, binds and listens (not yet serving: see start()).
  /// Throws ViewError: "--bind 'x' is not an IP address", "cannot listen on 127.0.0.1:8765: Address
  /// already in use", "--web folder '/x' has no index.html", "three.js not found in '/y' (run npm ci
  /// in bringup/web)".
  ViewServer(const ServerOptions& options, std::vector<Channel> channels);
  ~ViewServer();
  ViewServer(const ViewServer&) = delete;
  ViewServer& operator=(const ViewServer&) = delete;

  /// Starts the I/O thread. stop() (also from the destructor) closes every connection and joins it.
  void start();
  void stop() noexcept;

  /// The port actually listened on (the chosen one when ServerOptions::port is 0).
  int port() const { return port_; }
  /// "http://127.0.0.1:8765" (IPv6 addresses in brackets).
  std::string url() const;

  /// Sends `payload` as messageData to every subscription of `channel` (thread-safe; the frame is built
  /// and sent on the I/O thread). `stamp_ns`: the message's time [ns since the Unix epoch].
  void publish(std::uint32_t channel, std::uint64_t stamp_ns, std::shared_ptr<const std::string> payload);
  /// True if any client is subscribed to `channel` (thread-safe, may lag by one message).
  bool subscribed(std::uint32_t channel) const;

  const ServerStats& stats() const { return stats_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int port_ = 0;
  ServerStats stats_;
};

}  // namespace reflex::view_node
