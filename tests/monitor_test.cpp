// The web monitor (coordinator/monitor.h) over HTTP against a real coordinator process: login
// and sessions, the cookie's attributes, CSRF and cross-site refusals, tenant isolation, the
// buttons' operations, revocation on SIGHUP, and the loopback rules without a token file. The
// page itself in a real browser is clients/browser's test.
#include <gtest/gtest.h>
#include <httplib.h>

#include <csignal>
#include <nlohmann/json.hpp>
#include <regex>
#include <thread>

#include "engine/image_io.h"
#include "tests/support/farm.h"

namespace rf::test {
namespace {

const std::string kCornell = "scenes/cornell-box/scene.json";

int monitor_port(Process& coordinator) {
  std::smatch m;
  std::regex re("monitor port ([0-9]+)");
  std::string log;
  for (int i = 0; i < 250; ++i) {
    log = coordinator.log();
    if (std::regex_search(log, m, re)) return std::stoi(m[1]);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ADD_FAILURE() << "no monitor port in the log:\n" << log;
  return 0;
}

// A browser's view of the monitor: its cookie and CSRF token once logged in.
struct Browser {
  explicit Browser(int port) : http("127.0.0.1", port), port(port) {}
  httplib::Client http;
  int port;
  std::string cookie, csrf;

  httplib::Result login(const std::string& token) {
    auto r = http.Post("/api/login", nlohmann::json{{"token", token}}.dump(), "application/json");
    if (r && r->status == 200) {
      std::string set = r->get_header_value("Set-Cookie");
      cookie = set.substr(0, set.find(';'));
      csrf = nlohmann::json::parse(r->body)["csrf"];
    }
    return r;
  }
  httplib::Headers headers(bool with_csrf = true) const {
    httplib::Headers h;
    if (!cookie.empty()) h.emplace("Cookie", cookie);
    if (with_csrf && !csrf.empty()) h.emplace("X-CSRF-Token", csrf);
    return h;
  }
  httplib::Result get(const std::string& path) { return http.Get(path.c_str(), headers()); }
  httplib::Result post(const std::string& path, httplib::Headers h) {
    return http.Post(path.c_str(), h, "{}", "application/json");
  }
  httplib::Result post(const std::string& path) { return post(path, headers()); }
};

int status_of(const httplib::Result& r) { return r ? r->status : -1; }

// A coordinator with a monitor and a token file of two client tenants, a and b, and a worker;
// client commands use a's token, workers w's.
struct TwoTenants {
  explicit TwoTenants(const std::string& tag)
      : dir(make_temp_dir(tag)),
        a(make_token(dir, "a", "--role client --tenant a")),
        b(make_token(dir, "b", "--role client --tenant b")),
        w(make_token(dir, "w", "--role worker --tenant farm")),
        farm(tag, 30, token_file(dir, {&a, &b, &w}), {"--monitor-listen", "127.0.0.1:0"}),
        port(monitor_port(farm.coordinator())) {
    farm.client_token_file = a.file;
    farm.worker_token_file = w.file;
  }
  static std::string token_file(const std::string& dir, const std::vector<const Token*>& tokens) {
    write_token_file(dir + "/tokens", tokens);
    return dir + "/tokens";
  }
  std::string dir;
  Token a, b, w;
  Farm farm;
  int port;
};

std::vector<std::string> job_ids(const httplib::Result& r) {
  std::vector<std::string> ids;
  if (!r || r->status != 200) return ids;
  const nlohmann::json body = nlohmann::json::parse(r->body);  // outlives the loop
  for (const auto& j : body["jobs"]) ids.push_back(j["job_id"]);
  return ids;
}

TEST(Monitor, SessionsCookiesCsrfAndTenants) {
  TwoTenants t("monitor-auth");
  Farm& farm = t.farm;
  const Token &a = t.a, &b = t.b, &w = t.w;
  const int port = t.port;
  ASSERT_GT(port, 0);
  const std::string job = farm.submit(kCornell + " --spp 4 --passes 2 --res 16x16 --require gpu");

  Browser anon(port);
  auto page = anon.http.Get("/");
  ASSERT_EQ(status_of(page), 200);
  EXPECT_NE(page->body.find("rayfarm monitor"), std::string::npos);
  EXPECT_NE(page->get_header_value("Content-Security-Policy").find("script-src 'self'"),
            std::string::npos);
  EXPECT_EQ(page->get_header_value("X-Frame-Options"), "DENY");
  EXPECT_EQ(status_of(anon.get("/api/jobs")), 401) << "the API needs a session";
  EXPECT_EQ(status_of(anon.get("/api/workers")), 401);
  EXPECT_EQ(status_of(anon.post("/api/jobs/" + job + "/cancel")), 401);

  // Logins: an unknown token, a worker's token, a client's.
  EXPECT_EQ(status_of(anon.login("rft_" + std::string(64, '0'))), 401);
  EXPECT_EQ(status_of(anon.login(w.token)), 403) << "a worker token cannot log in";
  EXPECT_EQ(status_of(anon.http.Post("/api/login", "not json", "application/json")), 400);
  Browser alice(port);
  auto in = alice.login(a.token);
  ASSERT_EQ(status_of(in), 200);
  const std::string set_cookie = in->get_header_value("Set-Cookie");
  EXPECT_NE(set_cookie.find("HttpOnly"), std::string::npos) << set_cookie;
  EXPECT_NE(set_cookie.find("SameSite=Strict"), std::string::npos) << set_cookie;
  EXPECT_EQ(set_cookie.find("Secure"), std::string::npos) << "plain HTTP: " << set_cookie;
  EXPECT_EQ(set_cookie.find(a.token), std::string::npos) << "the cookie never holds the token";
  EXPECT_EQ(set_cookie.find(a.token.substr(4, 16)), std::string::npos);
  EXPECT_EQ(nlohmann::json::parse(in->body)["tenant"], "a");

  // Alice sees her job; Bob does not, and cannot operate on it.
  auto listed = alice.get("/api/jobs");
  EXPECT_EQ(job_ids(listed), std::vector<std::string>{job})
      << (listed ? listed->body : "no answer");
  auto detail = alice.get("/api/jobs/" + job);
  ASSERT_EQ(status_of(detail), 200);
  EXPECT_EQ(nlohmann::json::parse(detail->body)["frames"].size(), 1u);
  // A job's page asks for the frames it shows: the first N of them.
  const std::string range = farm.submit(kCornell +
                                        " --spp 4 --passes 2 --res 16x16 --frames "
                                        "1-5 --require gpu");
  auto three = alice.get("/api/jobs/" + range + "?frames=3");
  ASSERT_EQ(status_of(three), 200);
  nlohmann::json shown = nlohmann::json::parse(three->body);
  EXPECT_EQ(shown["frames"].size(), 3u);
  EXPECT_EQ(shown["frames_total"], 5);
  EXPECT_EQ(shown["frames"][2]["frame"], 3);
  EXPECT_EQ(status_of(alice.get("/api/jobs/" + range + "?frames=x")), 400);
  Browser bob(port);
  ASSERT_EQ(status_of(bob.login(b.token)), 200);
  EXPECT_TRUE(job_ids(bob.get("/api/jobs")).empty());
  EXPECT_NE(status_of(bob.get("/api/jobs/" + job)), 200);
  EXPECT_NE(status_of(bob.post("/api/jobs/" + job + "/cancel")), 200);

  // A POST needs the session's CSRF token and no cross-site origin.
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/pause", alice.headers(false))), 403);
  httplib::Headers wrong = alice.headers(false);
  wrong.emplace("X-CSRF-Token", bob.csrf);
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/pause", wrong)), 403);
  httplib::Headers foreign = alice.headers();
  foreign.emplace("Origin", "https://evil.example");
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/pause", foreign)), 403);
  httplib::Headers cross = alice.headers();
  cross.emplace("Sec-Fetch-Site", "cross-site");
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/cancel", cross)), 403);
  EXPECT_EQ(farm.status(job)["paused"], false) << "no refused request changed the job";

  // The buttons.
  httplib::Headers same = alice.headers();
  same.emplace("Origin", "http://127.0.0.1:" + std::to_string(port));
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/pause", same)), 200);
  EXPECT_EQ(farm.status(job)["paused"], true);
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/resume")), 200);
  EXPECT_EQ(farm.status(job)["paused"], false);
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/cancel")), 200);
  EXPECT_EQ(farm.status(job)["state"], "cancelled");
  EXPECT_EQ(status_of(alice.post("/api/jobs/" + job + "/retry")), 200);
  EXPECT_NE(farm.status(job)["state"], "cancelled");
  EXPECT_EQ(status_of(alice.post("/api/jobs/j999999/cancel")), 404);
  auto workers = alice.get("/api/workers");
  ASSERT_EQ(status_of(workers), 200);
  EXPECT_TRUE(nlohmann::json::parse(workers->body)["workers"].is_array());

  // Logging out ends the session; SIGHUP (the token file re-read) ends every other one.
  EXPECT_EQ(status_of(bob.post("/api/logout")), 200);
  EXPECT_EQ(status_of(bob.get("/api/jobs")), 401);
  EXPECT_EQ(status_of(alice.get("/api/jobs")), 200);
  farm.coordinator().signal(SIGHUP);
  for (int i = 0; i < 100 && status_of(alice.get("/api/jobs")) == 200; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(status_of(alice.get("/api/jobs")), 401) << "SIGHUP revokes sessions";
  ASSERT_EQ(status_of(alice.login(a.token)), 200) << "and a fresh login works";
  EXPECT_EQ(status_of(alice.get("/api/jobs")), 200);
}

// A frame's preview and noise history: the PNG is built once per merged prefix (a second ask is
// the cache's), changes as passes land, and the history has a point per prefix with the noise
// target beside it.
TEST(Monitor, PreviewsFollowThePassesAndAreCachedAndTheHistoryHasEveryPrefix) {
  TwoTenants t("monitor-preview");
  Farm& farm = t.farm;
  const Token &a = t.a, &b = t.b;
  const std::string& dir = t.dir;
  Browser alice(t.port);
  ASSERT_EQ(status_of(alice.login(a.token)), 200);
  const std::string job =
      farm.submit(kCornell + " --spp 512 --passes 16 --res 192x128 --noise-target 0.0001");
  const std::string preview = "/api/jobs/" + job + "/frames/0/preview.png";
  EXPECT_EQ(status_of(alice.get(preview)), 409) << "no pass merged yet";
  Process& worker = farm.worker();
  std::string first;
  auto first_at = std::chrono::steady_clock::now();
  for (int i = 0; i < 1000 && first.empty(); ++i) {
    auto r = alice.get(preview);
    if (status_of(r) == 200) {
      first = r->body;
      first_at = std::chrono::steady_clock::now();
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  ASSERT_FALSE(first.empty()) << worker.log();
  EXPECT_EQ(first.substr(1, 3), "PNG");
  ASSERT_LT(farm.status(job)["frames"][0]["passes_merged"].get<int>(), 16)
      << "the job ended before its first preview: it needs to be longer";
  ASSERT_EQ(farm.client("watch " + job).exit_code, 0);
  // A preview is rebuilt at most every 2 s (the refresh interval), whatever has merged.
  std::this_thread::sleep_until(first_at + std::chrono::milliseconds(2100));
  auto built = alice.get(preview);
  ASSERT_EQ(status_of(built), 200);
  EXPECT_EQ(built->get_header_value("X-Rayfarm-Preview"), "built");
  EXPECT_TRUE(built->body != first) << "the preview follows the merged passes";
  auto again = alice.get(preview);
  ASSERT_EQ(status_of(again), 200);
  EXPECT_EQ(again->get_header_value("X-Rayfarm-Preview"), "cached");
  EXPECT_TRUE(again->body == built->body);
  // 192x128 is under 256 on a side: the preview is the frame's size.
  write_text(dir + "/p.png", built->body);
  RgbImage img = read_rgb(dir + "/p.png");
  EXPECT_EQ(img.width, 192);
  EXPECT_EQ(img.height, 128);
  Browser bob(alice.port);
  ASSERT_EQ(status_of(bob.login(b.token)), 200);
  EXPECT_EQ(status_of(bob.get(preview)), 404) << "another tenant's frame";

  auto history = alice.get("/api/jobs/" + job + "/frames/0/history");
  ASSERT_EQ(status_of(history), 200);
  nlohmann::json h = nlohmann::json::parse(history->body);
  EXPECT_DOUBLE_EQ(h["noise_target"].get<double>(), 0.0001);
  const auto& points = h["points"];
  ASSERT_GE(points.size(), 2u);
  EXPECT_LE(points.size(), 16u);
  EXPECT_EQ(points.back()[1], 16) << "the last point is the whole frame";
  for (size_t i = 1; i < points.size(); ++i) {
    EXPECT_GT(points[i][1].get<int>(), points[i - 1][1].get<int>());
    EXPECT_GE(points[i][0].get<double>(), points[i - 1][0].get<double>());
  }
  EXPECT_TRUE(points.back()[2].is_number());
  EXPECT_EQ(status_of(bob.get("/api/jobs/" + job + "/frames/0/history")), 404);
  EXPECT_EQ(status_of(alice.get("/api/jobs/" + job + "/frames/7/preview.png")), 404);
  EXPECT_EQ(status_of(alice.get("/api/jobs/" + job + "/frames/99999999999/history")), 404)
      << "not a route: more than 10 digits";
}

// A session lasts no longer than its token.
TEST(Monitor, ASessionEndsWithItsToken) {
  std::string dir = make_temp_dir("monitor-expiry");
  Token a = make_token(dir, "a", "--role client --tenant a");
  // The token file's line with an expiry three seconds ahead (`token new --expires` takes whole
  // dates and times; this writes the line as it would).
  const int64_t soon = int64_t(std::time(nullptr)) + 3;
  char when[32];
  std::tm tm{};
  time_t t = soon;
  gmtime_r(&t, &tm);
  std::strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", &tm);
  std::string line = a.line.substr(0, a.line.find(" expires=")) + " expires=" + when;
  write_text(dir + "/tokens", line + "\n");
  Farm farm("monitor-exp", 30, dir + "/tokens", {"--monitor-listen", "127.0.0.1:0"});
  Browser alice(monitor_port(farm.coordinator()));
  auto in = alice.login(a.token);
  ASSERT_EQ(status_of(in), 200);
  EXPECT_LE(nlohmann::json::parse(in->body)["expires_unix"].get<int64_t>(), soon);
  EXPECT_EQ(status_of(alice.get("/api/jobs")), 200);
  std::this_thread::sleep_for(
      std::chrono::milliseconds(1000 * (soon - int64_t(std::time(nullptr))) + 1200));
  EXPECT_EQ(status_of(alice.get("/api/jobs")), 401);
  EXPECT_EQ(status_of(alice.login(a.token)), 401) << "the token itself has expired";
}

// With the gRPC port's TLS the monitor speaks HTTPS only, and its cookie is Secure.
TEST(Monitor, UnderTlsItServesHttpsAndSecureCookies) {
  std::string dir = make_temp_dir("monitor-tls");
  CommandResult pki =
      run_command("cd " + dir +
                  " && openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 "
                  "-nodes -keyout server.key -out server.pem -days 2 -subj /CN=localhost "
                  "-addext subjectAltName=DNS:localhost,IP:127.0.0.1");
  ASSERT_EQ(pki.exit_code, 0) << pki.output;
  Token a = make_token(dir, "a", "--role client --tenant a");
  write_token_file(dir + "/tokens", {&a});
  Farm farm("monitor-tls", 30, dir + "/tokens",
            {"--monitor-listen", "127.0.0.1:0", "--tls-cert", dir + "/server.pem", "--tls-key",
             dir + "/server.key"});
  const int port = monitor_port(farm.coordinator());
  ASSERT_GT(port, 0);
  EXPECT_NE(farm.coordinator().log().find("web monitor on https://"), std::string::npos);
  httplib::SSLClient https("127.0.0.1", port);
  https.set_ca_cert_path((dir + "/server.pem").c_str());
  https.enable_server_certificate_verification(true);
  auto in = https.Post("/api/login", nlohmann::json{{"token", a.token}}.dump(), "application/json");
  ASSERT_EQ(status_of(in), 200) << (in ? "" : httplib::to_string(in.error()));
  EXPECT_NE(in->get_header_value("Set-Cookie").find("; Secure"), std::string::npos)
      << in->get_header_value("Set-Cookie");
  httplib::Client plain("127.0.0.1", port);
  plain.set_connection_timeout(5);
  plain.set_read_timeout(5);
  auto p = plain.Get("/api/jobs");
  EXPECT_TRUE(!p || p->status != 200) << "plain HTTP on the HTTPS port";
}

// Without a token file: loopback only, no login, and only loopback Host names (a page of
// another site reaching 127.0.0.1 through a DNS name of its own is refused).
TEST(Monitor, WithoutATokenFileItIsLoopbackOnly) {
  Farm farm("monitor-open", 30, "", {"--monitor-listen", "127.0.0.1:0"});
  const int port = monitor_port(farm.coordinator());
  Browser local(port);
  auto in = local.http.Post("/api/login", "{}", "application/json");
  ASSERT_EQ(status_of(in), 200);
  EXPECT_TRUE(nlohmann::json::parse(in->body)["open"].get<bool>());
  local.cookie =
      in->get_header_value("Set-Cookie").substr(0, in->get_header_value("Set-Cookie").find(';'));
  EXPECT_EQ(status_of(local.get("/api/jobs")), 200);
  httplib::Headers rebound = local.headers();
  rebound.emplace("Host", "evil.example:" + std::to_string(port));
  auto r = local.http.Get("/api/jobs", rebound);
  EXPECT_EQ(status_of(r), 403);

  std::string dir = make_temp_dir("monitor-open-wide");
  CommandResult wide = run_command(rayfarm_binary() + " coordinator --listen 127.0.0.1:0 " +
                                   "--state-dir " + dir + " --monitor-listen 0.0.0.0:0");
  EXPECT_EQ(wide.exit_code, 1) << wide.output;
  EXPECT_NE(wide.output.find("--monitor-listen 0.0.0.0:0 without --token-file"), std::string::npos)
      << wide.output;
}

}  // namespace
}  // namespace rf::test
