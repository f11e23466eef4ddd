// The web monitor (docs/farm.md "Web monitor"): a page and a JSON API on an HTTP port of the
// coordinator's (--monitor-listen), served by cpp-httplib from the core's own calls, no gRPC.
//
// Authentication is the gRPC API's: a login with a client or admin token makes a server-side
// session bound to that token's principal; the cookie holds a random session id, never the
// token (HttpOnly, SameSite=Strict, Secure under TLS). A session ends at logout, after
// MonitorOptions::session_seconds, when its token expires, and when SIGHUP re-reads the token
// file (revoke_sessions). Every POST needs the session's CSRF token in X-CSRF-Token and no
// cross-site Origin. A tenant sees and operates on its own jobs only (the core's Caller rules).
//
// Without a token file the port, like the gRPC one, listens on loopback only; every browser on
// this machine is then an admin, and requests must name a loopback Host (no DNS rebinding).
#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "coordinator/core.h"
#include "farm/auth.h"

namespace rf {

struct MonitorOptions {
  std::string listen;             // HOST:PORT (port 0: any free one)
  std::string tls_cert, tls_key;  // HTTPS with these PEM files (the gRPC port's) when set
  bool open = false;              // no token file: loopback only, no login
  double session_seconds = 12 * 3600;
  size_t max_sessions = 10000;
  int threads = 8;
};

// Who a presented token is, or nothing with the reason (unknown, expired).
using TokenCheck =
    std::function<std::optional<Principal>(const std::string& token, std::string* why)>;

class Monitor {
 public:
  // Binds and starts serving; throws naming the address when it cannot.
  Monitor(Coordinator& core, const MonitorOptions& options, TokenCheck check);
  ~Monitor();
  int port() const;
  // Ends every session (the token file was re-read: a token taken out must not live on in a
  // browser).
  void revoke_sessions();
  size_t sessions() const;
  uint64_t previews_built() const;  // PNGs made (the rest came from the cache)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace rf
