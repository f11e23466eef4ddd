// Bearer tokens and roles (docs/security.md), free of gRPC: the coordinator's token file, the
// lookup of a presented token, and the client side's choice of token. service.cpp checks every
// call against a TokenTable in one place; the CLI and the worker attach their token to every
// call through their channel (farm/channel.h).
//
// A token is "rft_" and 64 hex digits (256 random bits). The coordinator stores only its
// SHA-256, one line per token:
//
//   # sha256-of-token                                                  role    tenant   [expiry]
//   9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08   client  shot42
//   expires=2027-06-30T00:00:00Z
//
// Roles: client (jobs of its tenant), worker (the worker service), admin (everything, all
// tenants). Digests are compared in constant time, every entry every time.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace rf {

enum class Role { Client, Worker, Admin };
const char* role_name(Role r);  // "client", "worker", "admin"
std::optional<Role> parse_role(std::string_view s);

// Who a call comes from once its token was checked. `id` names the token in logs and binds a
// worker's registration to it: "t:" and the first 12 hex digits of the token's SHA-256, never
// the token.
struct Principal {
  Role role = Role::Admin;
  std::string tenant;
  std::string id;
  std::optional<int64_t> expires_unix;  // the token's expiry, if it has one
};

struct TokenFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct TokenEntry {
  std::string sha256;  // 64 lower-case hex digits
  Role role = Role::Client;
  std::string tenant;
  std::optional<int64_t> expires_unix;
  int line = 0;
};

class TokenTable {
 public:
  // Parses a token file; throws TokenFileError naming the file and line of the first problem.
  static TokenTable load(const std::string& path);
  static TokenTable parse(const std::string& text, const std::string& name);

  enum class Check { Accepted, Unknown, Expired };
  // Looks a presented token up; fills `who` when it is accepted.
  Check check(std::string_view token, int64_t now_unix, Principal* who) const;
  size_t size() const { return entries_.size(); }

 private:
  std::vector<TokenEntry> entries_;
};

// 256 random bits from the OS as "rft_" + 64 hex digits.
std::string new_token();
// The line of a token file that accepts `token`.
std::string token_file_line(const std::string& token, Role role, const std::string& tenant,
                            std::optional<int64_t> expires_unix);
// "2027-06-30T00:00:00Z" (or a date, "2027-06-30") as Unix seconds; nothing if malformed.
std::optional<int64_t> parse_utc_time(std::string_view s);
std::string format_utc_time(int64_t unix_seconds);
// "t:" + the first 12 hex digits of the token's SHA-256 (Principal::id).
std::string token_id(std::string_view token);

// Where a coordinator without a token file may listen (its gRPC port and its monitor): a host
// that only reaches this machine (127.0.0.0/8, ::1, localhost), `host_of` an address or a Host
// header ("HOST:PORT", "[V6]:PORT", "HOST"); `loopback_listen` also takes Unix sockets.
std::string host_of(const std::string& host_port);
bool loopback_host(const std::string& host);
bool loopback_listen(const std::string& listen);

// The token a client or worker sends: the file given (--token-file), else $RAYFARM_TOKEN_FILE,
// else $RAYFARM_TOKEN, else none (""). Surrounding whitespace is dropped. Throws
// std::runtime_error naming the file when it cannot be read or holds no token.
std::string client_token(const std::string& token_file);

}  // namespace rf
