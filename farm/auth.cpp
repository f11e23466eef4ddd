#include "farm/auth.h"

#include <openssl/crypto.h>
#include <openssl/rand.h>

#include <cctype>
#include <cstdlib>
#include <ctime>
#include <sstream>

#include "engine/digest.h"
#include "farm/blob_store.h"  // is_sha256_hex

namespace rf {

const char* role_name(Role r) {
  switch (r) {
    case Role::Client:
      return "client";
    case Role::Worker:
      return "worker";
    case Role::Admin:
      return "admin";
  }
  return "?";
}

std::optional<Role> parse_role(std::string_view s) {
  if (s == "client") return Role::Client;
  if (s == "worker") return Role::Worker;
  if (s == "admin") return Role::Admin;
  return std::nullopt;
}

namespace {

bool valid_tenant(const std::string& t) {
  if (t.empty() || t.size() > 64) return false;
  for (char c : t)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.')
      return false;
  return true;
}

std::string trim(std::string s) {
  size_t b = s.find_first_not_of(" \t\r\n"), e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

}  // namespace

std::optional<int64_t> parse_utc_time(std::string_view s) {
  std::string text(s);
  if (text.size() == 10) text += "T00:00:00Z";
  std::tm tm{};
  const char* end = strptime(text.c_str(), "%Y-%m-%dT%H:%M:%SZ", &tm);
  if (!end || *end != '\0') return std::nullopt;
  return int64_t(timegm(&tm));
}

std::string format_utc_time(int64_t t) {
  std::time_t tt = std::time_t(t);
  std::tm tm{};
  gmtime_r(&tt, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

TokenTable TokenTable::parse(const std::string& text, const std::string& name) {
  TokenTable table;
  std::istringstream in(text);
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::vector<std::string> f;
    for (std::string w; fields >> w;) f.push_back(w);
    if (f.empty()) continue;
    auto bad = [&](const std::string& why) {
      throw TokenFileError(name + ":" + std::to_string(n) + ": " + why);
    };
    if (f.size() < 3 || f.size() > 4)
      bad("expected 'SHA256 ROLE TENANT [expires=YYYY-MM-DDTHH:MM:SSZ]', got " +
          std::to_string(f.size()) + " fields");
    TokenEntry e;
    e.line = n;
    if (!is_sha256_hex(f[0]))
      bad("the first field must be the token's SHA-256 (64 lower-case hex digits), not the "
          "token itself");
    e.sha256 = f[0];
    std::optional<Role> role = parse_role(f[1]);
    if (!role) bad("role '" + f[1] + "' is not client, worker or admin");
    e.role = *role;
    if (!valid_tenant(f[2])) bad("tenant '" + f[2] + "' must be 1-64 of [A-Za-z0-9._-]");
    e.tenant = f[2];
    if (f.size() == 4) {
      const std::string prefix = "expires=";
      if (f[3].rfind(prefix, 0) != 0) bad("the fourth field must be expires=YYYY-MM-DDTHH:MM:SSZ");
      e.expires_unix = parse_utc_time(f[3].substr(prefix.size()));
      if (!e.expires_unix) bad("'" + f[3] + "' is not expires=YYYY-MM-DDTHH:MM:SSZ (UTC)");
    }
    for (const TokenEntry& other : table.entries_)
      if (other.sha256 == e.sha256)
        bad("the same token is listed on line " + std::to_string(other.line));
    table.entries_.push_back(std::move(e));
  }
  return table;
}

TokenTable TokenTable::load(const std::string& path) {
  std::string text;
  try {
    text = read_file_bytes(path);
  } catch (const std::runtime_error& e) {
    throw TokenFileError(std::string(e.what()) + " (the token file)");
  }
  return parse(text, path);
}

TokenTable::Check TokenTable::check(std::string_view token, int64_t now_unix,
                                    Principal* who) const {
  std::string digest = sha256_hex(token);
  const TokenEntry* match = nullptr;
  for (const TokenEntry& e : entries_)  // every entry, each compared in constant time
    if (CRYPTO_memcmp(e.sha256.data(), digest.data(), digest.size()) == 0) match = &e;
  if (!match) return Check::Unknown;
  if (match->expires_unix && now_unix >= *match->expires_unix) return Check::Expired;
  *who = Principal{match->role, match->tenant, "t:" + digest.substr(0, 12), match->expires_unix};
  return Check::Accepted;
}

std::string new_token() {
  unsigned char bytes[32];
  if (RAND_bytes(bytes, sizeof bytes) != 1)
    throw std::runtime_error("cannot draw random bytes for a token (OpenSSL RAND_bytes)");
  static const char* hex = "0123456789abcdef";
  std::string out = "rft_";
  for (unsigned char b : bytes) {
    out.push_back(hex[b >> 4]);
    out.push_back(hex[b & 15]);
  }
  return out;
}

std::string token_file_line(const std::string& token, Role role, const std::string& tenant,
                            std::optional<int64_t> expires_unix) {
  if (!valid_tenant(tenant))
    throw std::invalid_argument("tenant '" + tenant + "' must be 1-64 of [A-Za-z0-9._-]");
  std::string line = sha256_hex(token) + " " + role_name(role) + " " + tenant;
  if (expires_unix) line += " expires=" + format_utc_time(*expires_unix);
  return line;
}

std::string host_of(const std::string& host_port) {
  const std::string& h = host_port;
  if (!h.empty() && h.front() == '[') return h.substr(1, h.find(']') - 1);
  if (h.find(':') != h.rfind(':')) return h;  // a bare IPv6 address
  return h.substr(0, h.rfind(':') == std::string::npos ? h.size() : h.rfind(':'));
}

bool loopback_host(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

bool loopback_listen(const std::string& listen) {
  if (listen.rfind("unix:", 0) == 0 || listen.rfind("unix-abstract:", 0) == 0) return true;
  return loopback_host(host_of(listen));
}

std::string token_id(std::string_view token) { return "t:" + sha256_hex(token).substr(0, 12); }

std::string client_token(const std::string& token_file) {
  std::string file = token_file;
  if (file.empty())
    if (const char* env = std::getenv("RAYFARM_TOKEN_FILE")) file = env;
  if (file.empty()) {
    const char* env = std::getenv("RAYFARM_TOKEN");
    return env ? trim(env) : std::string();
  }
  std::string token = trim(read_file_bytes(file));
  if (token.empty()) throw std::runtime_error(file + ": the token file is empty");
  if (token.find_first_of(" \t\r\n") != std::string::npos)
    throw std::runtime_error(file + ": holds more than one word; it must hold the token alone");
  return token;
}

}  // namespace rf
