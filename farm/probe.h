// Probes any gRPC server speaks: the standard health check (grpc.health.v1.Health/Check) and
// server reflection's service list, through stubs generated from the standard protos (Debian's
// grpc-proto; proto/CMakeLists.txt). Used by `rayfarm health` and by the tests.
#pragma once

#include <grpcpp/security/credentials.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace rf {

struct ProbeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// "SERVING", "NOT_SERVING", "SERVICE_UNKNOWN" or "UNKNOWN"; throws ProbeError (naming the address
// and gRPC's message) when the server cannot be reached or answers with an error.
// Plaintext unless `creds` says otherwise (farm/channel.h channel_credentials).
std::string check_health(const std::string& address, const std::string& service = "",
                         double timeout_seconds = 5,
                         std::shared_ptr<grpc::ChannelCredentials> creds = nullptr);

// The fully qualified names of the services the server lists through reflection.
std::vector<std::string> list_services(const std::string& address, double timeout_seconds = 5,
                                       std::shared_ptr<grpc::ChannelCredentials> creds = nullptr);

}  // namespace rf
