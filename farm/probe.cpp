#include "farm/probe.h"

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include "farm/channel.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "grpc/reflection/v1/reflection.pb.h"

namespace rf {

namespace {

namespace health = grpc::health::v1;
namespace reflection = grpc::reflection::v1;

// Servers built on gRPC before 1.57 (Debian 12's, so our coordinator) serve reflection as
// v1alpha only. Its C++ stubs cannot be generated here: libgrpc++_reflection already registers
// the v1alpha messages with protobuf, and registering them twice aborts the process at start.
// v1's messages are the same on the wire, so they are sent on the v1alpha method.
constexpr const char* kReflectionMethod =
    "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo";

// Waits for the completion-queue event `tag`. A failed step needs no check of its own: the
// call's final status says what went wrong.
void await(grpc::CompletionQueue& cq, void* tag) {
  void* got = nullptr;
  bool ok = false;
  while (cq.Next(&got, &ok))
    if (got == tag) return;
}

void drain(grpc::CompletionQueue& cq) {
  cq.Shutdown();
  void* tag;
  bool ok;
  while (cq.Next(&tag, &ok)) {
  }
}

std::shared_ptr<grpc::Channel> channel_to(const std::string& address,
                                          std::shared_ptr<grpc::ChannelCredentials> creds) {
  return grpc::CreateChannel(address, creds ? creds : grpc::InsecureChannelCredentials());
}

}  // namespace

std::string check_health(const std::string& address, const std::string& service, double timeout,
                         std::shared_ptr<grpc::ChannelCredentials> creds) {
  auto stub = health::Health::NewStub(channel_to(address, creds));
  grpc::ClientContext ctx;
  set_deadline(ctx, timeout);
  health::HealthCheckRequest request;
  request.set_service(service);
  health::HealthCheckResponse response;
  grpc::Status status = stub->Check(&ctx, request, &response);
  if (!status.ok())
    throw ProbeError(address + ": health check failed: " + status.error_message() + " (code " +
                     std::to_string(int(status.error_code())) + ")");
  switch (response.status()) {
    case health::HealthCheckResponse::SERVING:
      return "SERVING";
    case health::HealthCheckResponse::NOT_SERVING:
      return "NOT_SERVING";
    case health::HealthCheckResponse::SERVICE_UNKNOWN:
      return "SERVICE_UNKNOWN";
    default:
      return "UNKNOWN";
  }
}

std::vector<std::string> list_services(const std::string& address, double timeout,
                                       std::shared_ptr<grpc::ChannelCredentials> creds) {
  grpc::TemplatedGenericStub<reflection::ServerReflectionRequest,
                             reflection::ServerReflectionResponse>
      stub(channel_to(address, creds));
  grpc::ClientContext ctx;
  set_deadline(ctx, timeout);
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(&ctx, kReflectionMethod, &cq);
  int start = 0, write = 0, done = 0, read = 0, finish = 0;
  call->StartCall(&start);
  await(cq, &start);
  reflection::ServerReflectionRequest request;
  request.set_list_services("");
  call->Write(request, &write);
  await(cq, &write);
  call->WritesDone(&done);
  await(cq, &done);
  reflection::ServerReflectionResponse response;
  call->Read(&response, &read);
  await(cq, &read);
  grpc::Status status;
  call->Finish(&status, &finish);
  await(cq, &finish);
  drain(cq);
  if (!status.ok()) throw ProbeError(address + ": reflection failed: " + status.error_message());
  std::vector<std::string> names;
  for (const reflection::ServiceResponse& s : response.list_services_response().service())
    names.push_back(s.name());
  return names;
}

}  // namespace rf
