// Plain sockets on loopback, for tests that speak to a server below gRPC: an HTTP GET of the
// metrics page, and connections that send nothing (a client that never finishes its handshake).
#pragma once

#include <string>

namespace rf::test {

// A TCP connection to 127.0.0.1:port, or -1.
int connect_loopback(int port);
// GET http://127.0.0.1:port/path (HTTP/1.0: the server closes when done); the body of a 200
// answer, else "" with the reason in `error`.
std::string http_get(int port, const std::string& path, std::string& error);
// Whether the server has closed the connection: waits up to timeout_s for EOF or an error.
bool closed_by_peer(int fd, double timeout_s);

}  // namespace rf::test
