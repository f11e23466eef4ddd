// Client-side gRPC plumbing shared by the worker and the client commands (DESIGN.md
// "Coordinator": every RPC has a deadline; workers keep alive at most a third of the lease time
// and reconnect with capped, jittered backoff).
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <random>
#include <string>

namespace rf {

// How a client shows itself to a coordinator: its bearer token (farm/auth.h) and, for TLS, PEM
// text: the CA that signed the coordinator's certificate (empty: plaintext) and, for mutual
// TLS, this client's certificate and key.
struct ClientCredentials {
  std::string token;
  std::string tls_ca, tls_cert, tls_key;
};

// The token (farm/auth.h client_token) and the PEM files named, each else from its environment
// variable: RAYFARM_TLS_CA, RAYFARM_TLS_CERT, RAYFARM_TLS_KEY. Throws std::runtime_error naming
// a file that cannot be read, or a certificate given without its key.
ClientCredentials load_client_credentials(const std::string& token_file, std::string tls_ca_file,
                                          std::string tls_cert_file, std::string tls_key_file);

// TLS channel credentials when tls_ca is set, else plaintext.
std::shared_ptr<grpc::ChannelCredentials> channel_credentials(const ClientCredentials& creds);

// A channel to a coordinator. Reconnect attempts back off (jittered by gRPC) from 100 ms up to
// 2 s, so a restarted coordinator is found again within about 2 s. With keepalive_seconds > 0
// it also pings that often (the coordinator permits it), so a partition is noticed in time.
// A non-empty token goes with every call on the channel as "authorization: Bearer TOKEN" call
// metadata, added by a client interceptor.
std::shared_ptr<grpc::Channel> coordinator_channel(const std::string& address,
                                                   const ClientCredentials& creds,
                                                   int keepalive_seconds = 0);

// Every RPC has a deadline. With wait_for_ready the call waits for the channel to (re)connect
// within it, instead of failing at once while the coordinator restarts.
void set_deadline(grpc::ClientContext& ctx, double seconds, bool wait_for_ready = false);

// What an UNAVAILABLE answer most likely means, as " (...)" to append to its message: a TLS
// handshake that failed (gRPC says only "tcp handshaker shutdown" or "Ssl handshake failed"), a
// TLS coordinator dialled in plaintext, or no coordinator at `address`.
std::string unavailable_hint(const grpc::Status& status, const std::string& address, bool tls);

// A failure worth retrying: the coordinator is unreachable or slow, not refusing the request.
bool transient(const grpc::Status& status);

// Capped exponential backoff: first * 2^attempt seconds, at most cap, times a factor drawn from
// [0.5, 1] so that clients who lost the same coordinator do not come back in lockstep.
double backoff_seconds(int attempt, double first, double cap, std::mt19937& rng);

}  // namespace rf
