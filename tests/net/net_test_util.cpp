#include "net_test_util.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "gmr/ops/convert.h"
#include "gmr/io/motion_file.h"
#include "gmr/wire/framing.h"
#include "test_data.h"

namespace gmr::test {

std::filesystem::path cmu_file() { return data_file("bvh/cmu/02_01.bvh"); }

std::vector<server::LibraryEntry> test_library() {
  auto lib = server::builtin_library();
  if (have_data()) {
    auto m = load_motion(cmu_file());
    if (m.ok()) {
      auto pre = to_pre_rotation(*m);
      if (pre.ok()) {
        server::LibraryEntry& e = lib.emplace_back();
        e.name = "cmu/02_01";
        e.source = cmu_file().string();
        e.motion = std::make_shared<const Motion>(std::move(pre).value());
      }
    }
  }
  return lib;
}

namespace {
// The tests overload the server on purpose: no send budget unless a test
// sets one of its own. Two I/O threads unless a test picks: whatever the
// machine, clients land in turn on the control loop's thread and on another
// one, so every test crosses threads (and TSan sees it).
constexpr std::size_t kTestIoThreads = 2;
server::ServerConfig test_config(server::ServerConfig cfg) {
  if (cfg.io_threads == 0) cfg.io_threads = kTestIoThreads;
  cfg.port = 0;
  cfg.udp_port = 0;
  cfg.bind_address = "127.0.0.1";
  cfg.max_catch_up = std::chrono::hours(1);
  if (cfg.send_budget == server::ServerConfig{}.send_budget) cfg.send_budget = 0;
  return cfg;
}
}  // namespace

TestServer::TestServer(server::ServerConfig cfg, std::vector<server::LibraryEntry> library)
    : server(test_config(std::move(cfg)), std::move(library)) {
  // Warnings and errors only: the tests provoke many closed connections.
  spdlog::set_level(spdlog::level::warn);
  server.start();
}

std::unique_ptr<client::Client> TestServer::connect(client::ClientOptions o) {
  // Under a sanitizer a retarget or a marker calibration takes seconds, and
  // more with the other tests on both cores: a slow reply, not a lost one.
  if (kSlowBuild && o.timeout == client::ClientOptions{}.timeout) o.timeout = kSlowBuildReplyTimeout;
  o.host = "127.0.0.1";
  o.port = port();
  auto c = client::Client::connect(o);
  EXPECT_TRUE(c.ok()) << c.error().to_string();
  if (!c.ok()) return nullptr;
  return std::move(c).value();
}

SilentListener::SilentListener() {
  fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in at{};
  at.sin_family = AF_INET;
  at.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t at_size = sizeof at;
  if (fd_ < 0 || ::bind(fd_, reinterpret_cast<sockaddr*>(&at), sizeof at) != 0 || ::listen(fd_, 16) != 0 ||
      ::getsockname(fd_, reinterpret_cast<sockaddr*>(&at), &at_size) != 0) {
    ADD_FAILURE() << "a silent listener: " << std::strerror(errno);
    return;
  }
  port_ = ntohs(at.sin_port);
}

SilentListener::~SilentListener() {
  if (fd_ >= 0) ::close(fd_);
}

RawConnection::RawConnection(std::uint16_t port, int receive_buffer) {
  fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
  if (receive_buffer > 0) ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_buffer, sizeof receive_buffer);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ADD_FAILURE() << "connect: " << std::strerror(errno);
    closed_ = true;
  }
}

RawConnection::~RawConnection() {
  if (fd_ >= 0) ::close(fd_);
}

void RawConnection::send_bytes(const std::string& bytes) {
  std::size_t sent = 0;
  while (sent < bytes.size()) {
    const ssize_t n = ::send(fd_, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return;  // the server may have closed already; tests check that separately
    sent += static_cast<std::size_t>(n);
  }
}

void RawConnection::send(const pb::ClientMessage& m) { send_bytes(wire::frame_message(m).value()); }

void RawConnection::shutdown_send() { ::shutdown(fd_, SHUT_WR); }

bool RawConnection::read_exact(char* out, std::size_t n, std::chrono::steady_clock::time_point deadline) {
  std::size_t got = 0;
  while (got < n) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return false;
    const ssize_t r = ::recv(fd_, out + got, n - got, 0);
    if (r <= 0) {
      closed_ = true;
      return false;
    }
    got += static_cast<std::size_t>(r);
  }
  return true;
}

std::optional<pb::ServerMessage> RawConnection::receive(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  char prefix[4];
  if (!read_exact(prefix, 4, deadline)) return std::nullopt;
  const auto n = wire::read_length_prefix(std::span<const std::uint8_t, 4>(reinterpret_cast<std::uint8_t*>(prefix), 4));
  if (n > (64u << 20)) return std::nullopt;
  std::string body(n, '\0');
  if (!read_exact(body.data(), n, deadline)) return std::nullopt;
  pb::ServerMessage m;
  if (!m.ParseFromString(body)) return std::nullopt;
  return m;
}

bool RawConnection::readable(std::chrono::milliseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  return ::poll(&p, 1, static_cast<int>(timeout.count())) > 0;
}

std::optional<pb::ServerMessage> RawConnection::reply(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return std::nullopt;
    auto m = receive(left);
    if (!m) return m;
    if (m->has_frame() || m->has_heartbeat()) continue;
    return m;
  }
}

bool RawConnection::wait_closed(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  char buf[4096];
  while (!closed_) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return false;
    const ssize_t r = ::recv(fd_, buf, sizeof buf, 0);
    if (r <= 0) closed_ = true;
  }
  return true;
}

pb::HelloReply RawConnection::handshake() {
  pb::ClientMessage m;
  m.set_request_id(1);
  m.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  m.mutable_hello()->set_client_name("raw-test");
  send(m);
  auto r = reply();
  EXPECT_TRUE(r && r->has_hello());
  return r && r->has_hello() ? r->hello() : pb::HelloReply{};
}

std::optional<std::uint32_t> RawConnection::create_view(std::uint64_t id, const std::string& motion) {
  pb::ClientMessage m;
  m.set_request_id(id);
  m.mutable_create_view()->set_motion(motion);
  send(m);
  const auto r = reply();
  if (!r || !r->has_view()) return std::nullopt;
  return r->view().view_id();
}

pb::ClientMessage request(std::uint64_t id) {
  pb::ClientMessage m;
  m.set_request_id(id);
  return m;
}

namespace {
struct Collected {
  std::mutex mutex;
  std::vector<client::ReceivedFrame> frames;
  Latch<client::SubscriptionEnd> ended;
};
}  // namespace

std::vector<client::ReceivedFrame> stream_all(client::Client& c, const client::ViewState& v, bool udp, bool float64,
                                              bool orientations, double rate_hz, std::uint64_t* out_dropped) {
  auto col = std::make_shared<Collected>();
  client::SubscribeOptions o;
  o.udp = udp;
  o.float64 = float64;
  o.orientations = orientations;
  o.speed = rate_hz * v.frame_time;  // rate = speed / frame_time, one frame per tick
  // No staleness bound: a frame is delivered or counted in out_dropped,
  // however slow the build (a late frame would otherwise vanish uncounted
  // into the client's frames_stale).
  o.max_staleness = std::chrono::milliseconds(0);
  auto sub = c.subscribe(
      v.id, o,
      [col](const client::ReceivedFrame& f) {
        std::lock_guard lock(col->mutex);
        col->frames.push_back(f);
      },
      [col](const client::SubscriptionEnd& e) { col->ended.set(e); });
  EXPECT_TRUE(sub.ok()) << sub.error().to_string();
  if (!sub.ok()) return {};
  auto end = col->ended.wait();
  EXPECT_TRUE(end.has_value()) << "the stream did not end";
  if (end) {
    EXPECT_EQ(end->reason, "end of motion");
    if (out_dropped) *out_dropped = end->frames_dropped;
  }
  std::lock_guard lock(col->mutex);
  return col->frames;
}

void expect_delivered_or_counted(std::size_t delivered, std::uint64_t dropped, std::size_t total) {
  EXPECT_EQ(delivered + dropped, total) << "every frame delivered, or replaced and counted";
  EXPECT_GE(delivered * 2, total) << "most frames delivered";
}

void LibraryMotionTest::SetUp() {
  if (GetParam() != "walk") GMR_REQUIRE_DATA();
  server_ = std::make_unique<TestServer>();
  client_ = server_->connect();
  ASSERT_NE(client_, nullptr);
  for (const auto& e : test_library()) {
    if (e.name == GetParam()) source_ = e.motion;
  }
  ASSERT_NE(source_, nullptr) << "no motion " << GetParam();
}

Certificate::~Certificate() {
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
}

CommandRun run_command(const std::string& command_line) {
  CommandRun r;
  FILE* p = ::popen((command_line + " 2>&1").c_str(), "r");
  if (!p) return r;
  std::array<char, 65536> buf;
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;) r.out.append(buf.data(), n);
  const int st = ::pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  r.signalled = WIFSIGNALED(st);
  return r;
}

std::unique_ptr<Certificate> self_signed(const std::string& names) {
  static int serial = 0;
  auto out = std::make_unique<Certificate>();
  out->dir = std::filesystem::temp_directory_path() /
             ("gmr-tls-" + std::to_string(::getpid()) + "-" + std::to_string(++serial));
  std::filesystem::create_directories(out->dir);
  out->cert = out->dir / "cert.pem";
  out->key = out->dir / "key.pem";
  EVP_PKEY* key = EVP_EC_gen("P-256");
  X509* x = X509_new();
  X509_set_version(x, 2);
  ASN1_INTEGER_set(X509_get_serialNumber(x), serial);
  X509_gmtime_adj(X509_getm_notBefore(x), -60);
  X509_gmtime_adj(X509_getm_notAfter(x), 3600);
  X509_set_pubkey(x, key);
  X509_NAME* name = X509_get_subject_name(x);
  X509_NAME_add_entry_by_txt(name, "CN", MBSTRING_ASC, reinterpret_cast<const unsigned char*>("gmr test"), -1, -1, 0);
  X509_set_issuer_name(x, name);
  X509V3_CTX ctx;
  X509V3_set_ctx_nodb(&ctx);
  X509V3_set_ctx(&ctx, x, x, nullptr, nullptr, 0);
  for (auto [nid, value] :
       {std::pair{NID_subject_alt_name, names.c_str()}, std::pair{NID_basic_constraints, "critical,CA:TRUE"}}) {
    X509_EXTENSION* ext = X509V3_EXT_conf_nid(nullptr, &ctx, nid, value);
    X509_add_ext(x, ext, -1);
    X509_EXTENSION_free(ext);
  }
  X509_sign(x, key, EVP_sha256());
  FILE* f = std::fopen(out->cert.c_str(), "w");
  PEM_write_X509(f, x);
  std::fclose(f);
  f = std::fopen(out->key.c_str(), "w");
  PEM_write_PrivateKey(f, key, nullptr, nullptr, 0, nullptr, nullptr);
  std::fclose(f);
  X509_free(x);
  EVP_PKEY_free(key);
  return out;
}

}  // namespace gmr::test
