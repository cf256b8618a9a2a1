// Raw sockets for gmr-soak's hostile clients: they must say what a real
// client never would, so they do not go through gmr::client. Blocking, with
// 1 s send and receive timeouts, so no attack can stall the soak itself.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cstdint>
#include <string>

#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/framing.h"

namespace gmr::soak {

// A TCP connection to host:port from `source` (an address of this host,
// e.g. 127.0.0.7, standing in for another machine; empty: any), or -1.
inline int raw_connect(const std::string& host, std::uint16_t port, const std::string& source = {},
                       int receive_buffer = 0) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  if (receive_buffer > 0) ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &receive_buffer, sizeof receive_buffer);
  timeval tv{1, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  if (!source.empty()) {
    sockaddr_in from{};
    from.sin_family = AF_INET;
    ::inet_pton(AF_INET, source.c_str(), &from.sin_addr);
    if (::bind(fd, reinterpret_cast<sockaddr*>(&from), sizeof from) != 0) {
      ::close(fd);
      return -1;
    }
  }
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  ::inet_pton(AF_INET, host.c_str(), &addr.sin_addr);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// Sends what the socket takes within its timeout; returns the bytes sent.
inline std::size_t send_all(int fd, const std::string& bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  return done;
}

inline void send_request(int fd, std::uint64_t id, ::gmr::stream::v1::ClientMessage m) {
  m.set_request_id(id);
  send_all(fd, gmr::wire::frame_message(m).value());
}

inline ::gmr::stream::v1::ClientMessage hello_message(const std::string& name, const std::string& token = {}) {
  ::gmr::stream::v1::ClientMessage m;
  m.mutable_hello()->set_protocol_version(gmr::wire::kProtocolVersion);
  m.mutable_hello()->set_client_name(name);
  if (!token.empty()) m.mutable_hello()->set_auth_token(token);
  return m;
}

// Reads and discards what is waiting (at most `bytes`), so a reply gets
// through; returns what recv returned (0: closed, -1: nothing in time).
inline ssize_t drain(int fd, std::size_t bytes) {
  std::string buf(bytes, '\0');
  return ::recv(fd, buf.data(), buf.size(), 0);
}

// One HTTP/1.1 request on a new connection; the status of the answer, or 0
// when none came within `timeout_s`.
inline int http_status(const std::string& host, std::uint16_t port, const std::string& path,
                       const std::string& host_header = {}, int timeout_s = 2) {
  const int fd = raw_connect(host, port);
  if (fd < 0) return 0;
  timeval tv{timeout_s, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  const std::string h = host_header.empty() ? host + ":" + std::to_string(port) : host_header;
  send_all(fd, "GET " + path + " HTTP/1.1\r\nHost: " + h + "\r\nConnection: close\r\n\r\n");
  std::string answer;
  char buf[256];
  while (answer.size() < 12) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    answer.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  if (answer.rfind("HTTP/1.1 ", 0) != 0 || answer.size() < 12) return 0;
  return std::stoi(answer.substr(9, 3));
}

// The whole body of GET path (for /metrics), empty when it failed.
inline std::string http_get(const std::string& host, std::uint16_t port, const std::string& path) {
  const int fd = raw_connect(host, port);
  if (fd < 0) return {};
  timeval tv{5, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  send_all(fd,
           "GET " + path + " HTTP/1.1\r\nHost: " + host + ":" + std::to_string(port) + "\r\nConnection: close\r\n\r\n");
  std::string answer;
  char buf[16384];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    answer.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fd);
  const auto body = answer.find("\r\n\r\n");
  return body == std::string::npos ? std::string{} : answer.substr(body + 4);
}

// Upgrades a new connection on the HTTP port to a WebSocket (`protocol`:
// gmr.stream.v1 or gmr.stream.v1.json) with a raw handshake; the socket, or
// -1 when the server did not answer 101.
inline int ws_connect(const std::string& host, std::uint16_t http_port, const std::string& protocol,
                      const std::string& source = {}) {
  const int fd = raw_connect(host, http_port, source);
  if (fd < 0) return -1;
  send_all(fd, "GET /ws HTTP/1.1\r\nHost: " + host + ":" + std::to_string(http_port) +
                   "\r\nConnection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n"
                   "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Protocol: " +
                   protocol + "\r\n\r\n");
  std::string answer;
  char c;
  while (answer.find("\r\n\r\n") == std::string::npos && answer.size() < 4096) {
    if (::recv(fd, &c, 1, 0) != 1) break;
    answer += c;
  }
  if (answer.rfind("HTTP/1.1 101", 0) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// A client-to-server WebSocket frame (masked with key 0, so the payload goes
// as it is): FIN set, `opcode` 1 text or 2 binary. `declared` is the length
// the header states (the payload's own size when 0).
inline std::string ws_frame(int opcode, const std::string& payload, std::uint64_t declared = 0) {
  const std::uint64_t n = declared != 0 ? declared : payload.size();
  std::string f;
  f += static_cast<char>(0x80 | opcode);
  if (n < 126) {
    f += static_cast<char>(0x80 | n);
  } else if (n < 65536) {
    f += static_cast<char>(0x80 | 126);
    f += static_cast<char>(n >> 8);
    f += static_cast<char>(n & 0xff);
  } else {
    f += static_cast<char>(0x80 | 127);
    for (int i = 7; i >= 0; --i) f += static_cast<char>((n >> (8 * i)) & 0xff);
  }
  f.append(4, '\0');
  return f + payload;
}

}  // namespace gmr::soak
