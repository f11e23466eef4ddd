#include "farm/channel.h"

#include "engine/digest.h"  // read_file_bytes
#include "farm/auth.h"

#include <grpcpp/support/client_interceptor.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace rf {

namespace {

// Adds the bearer token to the initial metadata of every call on its channel.
class TokenInterceptor final : public grpc::experimental::Interceptor {
 public:
  explicit TokenInterceptor(const std::string* header) : header_(header) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            grpc::experimental::InterceptionHookPoints::PRE_SEND_INITIAL_METADATA))
      methods->GetSendInitialMetadata()->emplace("authorization", *header_);
    methods->Proceed();
  }

 private:
  const std::string* header_;
};

class TokenInterceptorFactory final : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  explicit TokenInterceptorFactory(const std::string& token) : header_("Bearer " + token) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(
      grpc::experimental::ClientRpcInfo*) override {
    return new TokenInterceptor(&header_);
  }

 private:
  std::string header_;  // lives as long as the channel, which owns the factory
};

}  // namespace

namespace {

std::string from_env(std::string value, const char* var) {
  if (value.empty())
    if (const char* env = std::getenv(var)) value = env;
  return value;
}

}  // namespace

ClientCredentials load_client_credentials(const std::string& token_file, std::string ca,
                                          std::string cert, std::string key) {
  ClientCredentials c;
  c.token = client_token(token_file);
  ca = from_env(ca, "RAYFARM_TLS_CA");
  cert = from_env(cert, "RAYFARM_TLS_CERT");
  key = from_env(key, "RAYFARM_TLS_KEY");
  if (cert.empty() != key.empty())
    throw std::runtime_error("a TLS client certificate needs its key, and a key its certificate");
  if (!cert.empty() && ca.empty())
    throw std::runtime_error("a TLS client certificate needs the coordinator's CA (--tls-ca)");
  if (!ca.empty()) c.tls_ca = read_file_bytes(ca);
  if (!cert.empty()) c.tls_cert = read_file_bytes(cert);
  if (!key.empty()) c.tls_key = read_file_bytes(key);
  return c;
}

std::shared_ptr<grpc::ChannelCredentials> channel_credentials(const ClientCredentials& c) {
  if (c.tls_ca.empty()) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = c.tls_ca;
  o.pem_private_key = c.tls_key;
  o.pem_cert_chain = c.tls_cert;
  return grpc::SslCredentials(o);
}

std::shared_ptr<grpc::Channel> coordinator_channel(const std::string& address,
                                                   const ClientCredentials& creds,
                                                   int keepalive_seconds) {
  grpc::ChannelArguments args;
  if (keepalive_seconds > 0) {
    args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, keepalive_seconds * 1000);
    args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, std::max(1, keepalive_seconds / 2) * 1000);
    args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  }
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  std::vector<std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>> interceptors;
  if (!creds.token.empty())
    interceptors.push_back(std::make_unique<TokenInterceptorFactory>(creds.token));
  return grpc::experimental::CreateCustomChannelWithInterceptors(
      address, channel_credentials(creds), args, std::move(interceptors));
}

void set_deadline(grpc::ClientContext& ctx, double seconds, bool wait_for_ready) {
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(int64_t(seconds * 1000)));
  if (wait_for_ready) ctx.set_wait_for_ready(true);
}

std::string unavailable_hint(const grpc::Status& s, const std::string& address, bool tls) {
  std::string m = s.error_message();
  for (char& c : m) c = char(std::tolower(static_cast<unsigned char>(c)));
  auto has = [&](const char* part) { return m.find(part) != std::string::npos; };
  // A server that refuses the client's certificate closes the socket mid-handshake.
  if (tls && (has("handshake") || has("ssl") || has("certificate") || has("socket closed") ||
              has("connection reset")))
    return " (the TLS handshake with " + address +
           " failed: does --tls-ca sign the coordinator's certificate, and does it name the host "
           "dialled? A coordinator without TLS, or one that wants a client certificate from "
           "another CA, fails the same way)";
  if (!tls && (has("socket closed") || has("connection reset")))
    return " (is the coordinator at " + address + " serving TLS? then give --tls-ca)";
  return " (is a coordinator running at " + address + "?)";
}

bool transient(const grpc::Status& s) {
  return s.error_code() == grpc::StatusCode::UNAVAILABLE ||
         s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED;
}

double backoff_seconds(int attempt, double first, double cap, std::mt19937& rng) {
  double base = first * std::ldexp(1.0, std::clamp(attempt, 0, 30));
  return std::min(cap, base) * std::uniform_real_distribution<double>(0.5, 1.0)(rng);
}

}  // namespace rf
