#include "farm/probe.h"

#include <google/protobuf/io/coded_stream.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <chrono>

namespace rf {

namespace {

using google::protobuf::io::CodedInputStream;

grpc::ByteBuffer to_buffer(const std::string& bytes) {
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

std::string to_string(const grpc::ByteBuffer& buf) {
  grpc::Slice slice;
  std::string out;
  std::vector<grpc::Slice> slices;
  if (buf.Dump(&slices).ok())
    for (const grpc::Slice& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

// The length-delimited fields numbered `field` of a protobuf message, in order.
std::vector<std::string> string_fields(const std::string& msg, uint32_t field) {
  std::vector<std::string> out;
  CodedInputStream in(reinterpret_cast<const uint8_t*>(msg.data()), int(msg.size()));
  while (uint32_t tag = in.ReadTag()) {
    uint32_t number = tag >> 3, type = tag & 7;
    if (type == 2) {
      uint32_t len = 0;
      std::string s;
      if (!in.ReadVarint32(&len) || !in.ReadString(&s, int(len))) break;
      if (number == field) out.push_back(std::move(s));
    } else if (type == 0) {
      uint64_t v;
      if (!in.ReadVarint64(&v)) break;
    } else if (type == 1) {
      uint64_t v;
      if (!in.ReadLittleEndian64(&v)) break;
    } else if (type == 5) {
      uint32_t v;
      if (!in.ReadLittleEndian32(&v)) break;
    } else {
      break;
    }
  }
  return out;
}

uint64_t varint_field(const std::string& msg, uint32_t field) {
  CodedInputStream in(reinterpret_cast<const uint8_t*>(msg.data()), int(msg.size()));
  uint64_t value = 0;
  while (uint32_t tag = in.ReadTag()) {
    uint64_t v = 0;
    if ((tag & 7) == 0) {
      if (!in.ReadVarint64(&v)) break;
      if ((tag >> 3) == field) value = v;
    } else if ((tag & 7) == 2) {
      uint32_t len = 0;
      if (!in.ReadVarint32(&len) || !in.Skip(int(len))) break;
    } else {
      break;
    }
  }
  return value;
}

std::string encode_string_field(uint32_t field, const std::string& s) {
  std::string out;
  out.push_back(char((field << 3) | 2));
  out.push_back(char(s.size()));  // short strings only (< 128 bytes)
  return out + s;
}

void wait_ok(grpc::CompletionQueue& cq, void* tag) {
  void* got = nullptr;
  bool ok = false;
  while (cq.Next(&got, &ok))
    if (got == tag) return;
}

std::chrono::system_clock::time_point deadline(double s) {
  return std::chrono::system_clock::now() + std::chrono::milliseconds(int64_t(s * 1000));
}

}  // namespace

std::string check_health(const std::string& address, const std::string& service, double timeout) {
  if (service.size() >= 128) throw ProbeError("health: service name too long");
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(deadline(timeout));
  grpc::CompletionQueue cq;
  grpc::ByteBuffer request = to_buffer(service.empty() ? "" : encode_string_field(1, service));
  auto call = stub.PrepareUnaryCall(&ctx, "/grpc.health.v1.Health/Check", request, &cq);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  int tag = 0;
  call->Finish(&response, &status, &tag);
  wait_ok(cq, &tag);
  cq.Shutdown();
  void* t;
  bool ok;
  while (cq.Next(&t, &ok)) {
  }
  if (!status.ok())
    throw ProbeError(address + ": health check failed: " + status.error_message() + " (code " +
                     std::to_string(int(status.error_code())) + ")");
  switch (varint_field(to_string(response), 1)) {
    case 1: return "SERVING";
    case 2: return "NOT_SERVING";
    case 3: return "SERVICE_UNKNOWN";
    default: return "UNKNOWN";
  }
}

std::vector<std::string> list_services(const std::string& address, double timeout) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(deadline(timeout));
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(
      &ctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  int start = 0, write = 0, done = 0, read = 0, finish = 0;
  call->StartCall(&start);
  wait_ok(cq, &start);
  // ServerReflectionRequest { list_services = 7: "" }
  call->Write(to_buffer(encode_string_field(7, "")), &write);
  wait_ok(cq, &write);
  call->WritesDone(&done);
  wait_ok(cq, &done);
  grpc::ByteBuffer response;
  call->Read(&response, &read);
  wait_ok(cq, &read);
  grpc::Status status;
  call->Finish(&status, &finish);
  wait_ok(cq, &finish);
  cq.Shutdown();
  void* t;
  bool ok;
  while (cq.Next(&t, &ok)) {
  }
  if (!status.ok())
    throw ProbeError(address + ": reflection failed: " + status.error_message());
  // ServerReflectionResponse.list_services_response = 6 { repeated ServiceResponse service = 1
  // { string name = 1 } }
  std::vector<std::string> names;
  for (const std::string& list : string_fields(to_string(response), 6))
    for (const std::string& svc : string_fields(list, 1))
      for (const std::string& name : string_fields(svc, 1)) names.push_back(name);
  return names;
}

}  // namespace rf
