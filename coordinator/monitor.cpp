#include "coordinator/monitor.h"

#include <openssl/crypto.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <cctype>
#include <chrono>
#include <climits>
#include <cmath>
#include <ctime>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "coordinator/errors.h"
#include "coordinator/monitor_page.h"
#include "engine/buffer_file.h"
#include "engine/image_io.h"
#include "farm/frame_range.h"
#include "httplib.h"

namespace rf {
namespace {

constexpr const char* kCookie = "rayfarm_session";

// 256 random bits as 64 hex digits (a token's, farm/auth.h, without its "rft_").
std::string random_hex() { return new_token().substr(4); }

bool equal_secret(const std::string& a, const std::string& b) {
  return a.size() == b.size() && CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

int64_t now_unix() { return int64_t(std::time(nullptr)); }

// "queued", "running", ... as the CLI's --json spells them ("JOB_QUEUED" without its prefix).
std::string state_text(JobState s) {
  std::string name = job_state_name(s);
  name = name.substr(name.rfind('_') + 1);
  for (char& c : name) c = char(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

nlohmann::json frame_json(const FrameStatus& f) {
  const FrameProgress& p = f.progress;
  return {{"frame", f.frame},
          {"passes_merged", p.passes_merged},
          {"passes_total", p.passes_total},
          {"spp", p.spp},
          // Not estimable before two passes: null, never 0 (as the CLI's --json).
          {"rel_mse",
           p.passes_merged >= 2 && std::isfinite(p.rel_mse) ? nlohmann::json(p.rel_mse) : nullptr},
          {"eta_seconds", p.eta_seconds >= 0 ? nlohmann::json(p.eta_seconds) : nullptr},
          {"done", p.done},
          {"stopped_on_target", p.stopped_on_target},
          {"run", f.run}};
}

// A job as the page lists it; with `frames`, its first `frames` frames too (the job's own page,
// which shows a dozen at a time: a job of 10,000 frames is not sent whole every 2 s).
nlohmann::json job_json(const JobStatus& j, size_t frames = 0) {
  uint64_t merged = 0, total = 0;
  int done = 0;
  double eta = 0, worst = 0;
  bool eta_known = true;
  for (const FrameStatus& f : j.frames) {
    const FrameProgress& p = f.progress;
    done += p.done;
    total += p.passes_total;
    merged += p.done ? p.passes_total : p.passes_merged;
    if (p.passes_merged >= 2 && std::isfinite(p.rel_mse)) worst = std::max(worst, p.rel_mse);
    if (!p.done) {
      if (p.eta_seconds < 0) eta_known = false;
      eta += std::max(0.0, p.eta_seconds);
    }
  }
  const bool ended = terminal(j.state);
  nlohmann::json out = {{"job_id", j.job_id},
                        {"name", j.name},
                        {"tenant", j.tenant},
                        {"state", state_text(j.state)},
                        {"paused", j.paused},
                        {"priority", j.priority},
                        {"progress", total ? double(merged) / double(total) : 0.0},
                        {"frames_done", done},
                        {"frames_total", j.frames.size()},
                        {"worst_rel_mse", worst > 0 ? nlohmann::json(worst) : nullptr},
                        {"eta_seconds", j.state == JobState::Completed    ? nlohmann::json(0.0)
                                        : ended || j.paused || !eta_known ? nlohmann::json(nullptr)
                                                                          : nlohmann::json(eta)},
                        {"core_seconds", j.core_seconds},
                        {"submitted_unix", j.submitted_unix},
                        {"ended_unix", j.ended_unix ? nlohmann::json(j.ended_unix) : nullptr},
                        {"error", j.error},
                        {"waiting_for", j.waiting_for}};
  if (frames) {
    nlohmann::json list = nlohmann::json::array();
    for (size_t i = 0; i < j.frames.size() && i < frames; ++i)
      list.push_back(frame_json(j.frames[i]));
    out["frames"] = std::move(list);
    out["held_frames"] = frame_range_text(j.held);
    out["noise_target"] = j.noise_target > 0 ? nlohmann::json(j.noise_target) : nullptr;
    out["scene_path"] = j.scene_path;
    out["required_tags"] = j.required_tags;
  }
  return out;
}

int http_status(ErrorCode c) {
  switch (c) {
    case ErrorCode::InvalidArgument:
      return 400;
    case ErrorCode::Unauthenticated:
      return 401;
    case ErrorCode::PermissionDenied:
      return 403;
    case ErrorCode::NotFound:
      return 404;
    case ErrorCode::FailedPrecondition:
      return 409;
    case ErrorCode::ResourceExhausted:
      return 429;
    case ErrorCode::Unavailable:
      return 503;
    default:
      return 500;
  }
}

// A frame's preview: one PNG per (frame, merged prefix), rebuilt at most every
// kPreviewRefreshSeconds however often pages ask, one build at a time per frame.
constexpr double kPreviewRefreshSeconds = 2.0;
constexpr int kPreviewSide = 256;
constexpr size_t kPreviewsKept = 1024;

struct PreviewEntry {
  std::mutex build;
  uint32_t passes = 0, run = 0;
  double built_at = -1e300;
  std::shared_ptr<const std::string> png;
};

FrameNumber frame_of(const std::string& text) {
  const long long n = std::stoll(text);  // the route allows at most 10 digits
  if (n < INT32_MIN || n > INT32_MAX)
    throw CoordinatorError(ErrorCode::InvalidArgument, "frame " + text + " is out of range");
  return FrameNumber(n);
}

// A list's page size: ?limit= (default 100, 1 to 1000).
size_t page_limit(const httplib::Request& req) {
  if (!req.has_param("limit")) return 100;
  try {
    return std::clamp<size_t>(std::stoul(req.get_param_value("limit")), 1, 1000);
  } catch (const std::exception&) {
    throw CoordinatorError(ErrorCode::InvalidArgument, "limit: not a number");
  }
}

double monotonic_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Session {
  Caller caller;
  std::string csrf;
  int64_t expires_unix = 0;
  bool admin = false;
};

}  // namespace

struct Monitor::Impl {
  Coordinator& core;
  MonitorOptions o;
  TokenCheck check;
  std::unique_ptr<httplib::Server> server;
  std::thread thread;
  int port = 0;
  mutable std::mutex mu;
  std::map<std::string, Session> sessions;  // by session id
  std::mutex previews_mu;
  // By (job, frame), with when each was last asked for (the least recent goes first when full).
  std::map<std::pair<std::string, FrameNumber>, std::pair<std::shared_ptr<PreviewEntry>, double>>
      previews;
  std::atomic<uint64_t> previews_built{0};

  Impl(Coordinator& c, MonitorOptions opt, TokenCheck t)
      : core(c), o(std::move(opt)), check(std::move(t)) {}

  static void reply(httplib::Response& res, int status, const nlohmann::json& body) {
    res.status = status;
    res.set_header("Cache-Control", "no-store");
    res.set_content(body.dump(), "application/json");
  }
  static void refuse(httplib::Response& res, int status, const std::string& why) {
    reply(res, status, {{"error", why}});
  }

  std::optional<Session> session_of(const httplib::Request& req) {
    const std::string cookie = req.get_header_value("Cookie");
    const std::string key = std::string(kCookie) + "=";
    std::string id;
    for (size_t at = 0; at < cookie.size();) {
      size_t end = cookie.find(';', at);
      if (end == std::string::npos) end = cookie.size();
      std::string part = cookie.substr(at, end - at);
      part.erase(0, part.find_first_not_of(' '));
      if (part.rfind(key, 0) == 0) id = part.substr(key.size());
      at = end + 1;
    }
    if (id.empty()) return std::nullopt;
    std::lock_guard lock(mu);
    auto it = sessions.find(id);
    if (it == sessions.end()) return std::nullopt;
    if (now_unix() >= it->second.expires_unix) {
      sessions.erase(it);
      return std::nullopt;
    }
    return it->second;
  }

  // Requests a browser on another site could make must not act: a POST needs the session's
  // CSRF token (which only a page of this origin can read) and no foreign Origin.
  bool same_origin(const httplib::Request& req) const {
    if (req.get_header_value("Sec-Fetch-Site") == "cross-site") return false;
    const std::string origin = req.get_header_value("Origin");
    if (origin.empty()) return true;
    const std::string scheme = o.tls_cert.empty() ? "http://" : "https://";
    return origin == scheme + req.get_header_value("Host");
  }

  std::string cookie(const std::string& id, int64_t max_age) const {
    std::string c = std::string(kCookie) + "=" + id +
                    "; Path=/; HttpOnly; SameSite=Strict; Max-Age=" +
                    std::to_string(std::max<int64_t>(0, max_age));
    if (!o.tls_cert.empty()) c += "; Secure";
    return c;
  }

  nlohmann::json session_json(const Session& s) const {
    return {{"csrf", s.csrf},   {"principal", s.caller.principal}, {"tenant", s.caller.tenant},
            {"admin", s.admin}, {"expires_unix", s.expires_unix},  {"open", o.open}};
  }

  Session new_session(const Caller& caller, bool admin, int64_t expires, std::string* id) {
    Session s{caller, random_hex().substr(0, 32), expires, admin};  // CSRF: 128 bits
    *id = random_hex();
    std::lock_guard lock(mu);
    if (sessions.size() >= o.max_sessions) {
      const int64_t now = now_unix();
      for (auto it = sessions.begin(); it != sessions.end();)
        it = it->second.expires_unix <= now ? sessions.erase(it) : std::next(it);
      if (sessions.size() >= o.max_sessions)
        throw CoordinatorError(ErrorCode::ResourceExhausted,
                               "too many monitor sessions; try again later");
    }
    sessions[*id] = s;
    return s;
  }

  // Runs an API handler for the request's session; answers 401 without one, 403 for a POST
  // without its CSRF token or from another site, and each refusal of the core with its code.
  void api(const httplib::Request& req, httplib::Response& res,
           const std::function<nlohmann::json(const Session&)>& f) {
    std::optional<Session> s = session_of(req);
    if (!s) return refuse(res, 401, "no session: log in with a client token");
    if (req.method == "POST") {
      if (!same_origin(req)) return refuse(res, 403, "cross-site request refused");
      if (!equal_secret(req.get_header_value("X-CSRF-Token"), s->csrf))
        return refuse(res, 403, "missing or wrong X-CSRF-Token");
    }
    try {
      reply(res, 200, f(*s));
    } catch (const CoordinatorError& e) {
      refuse(res, http_status(e.code), e.what());
    } catch (const std::exception& e) {
      refuse(res, 500, e.what());
    }
  }

  // The frame's preview PNG for this caller: cached while its merged prefix is the same, and
  // while the cached one is younger than the refresh interval. Built from the core's fetch
  // (which holds only the frame's own lock while it encodes), decoded, scaled and encoded here,
  // outside every lock of the core.
  std::shared_ptr<const std::string> preview(const Caller& caller, const std::string& job,
                                             FrameNumber frame, bool* built) {
    *built = false;
    // The frame alone (NOT_FOUND and tenants as everywhere), not the job's every frame.
    const FrameStatus status = core.frame_history(job, frame, caller).status;
    const FrameStatus* f = &status;  // (the history's points, at most 128, come along)
    if (f->progress.passes_merged == 0)
      throw CoordinatorError(ErrorCode::FailedPrecondition,
                             "frame " + std::to_string(frame) + " has no complete pass yet");
    std::shared_ptr<PreviewEntry> e;
    const double now = monotonic_seconds();
    {
      std::lock_guard lock(previews_mu);
      auto& slot = previews[{job, frame}];
      if (!slot.first) slot.first = std::make_shared<PreviewEntry>();
      slot.second = now;
      e = slot.first;
      if (previews.size() > kPreviewsKept) {
        auto oldest = previews.begin();
        for (auto it = previews.begin(); it != previews.end(); ++it)
          if (it->second.second < oldest->second.second) oldest = it;
        previews.erase(oldest);
      }
    }
    std::lock_guard build(e->build);
    if (e->png && e->run == f->run &&
        (e->passes == f->progress.passes_merged || now - e->built_at < kPreviewRefreshSeconds))
      return e->png;
    FrameImage image = core.fetch(job, frame, caller);
    auto png = std::make_shared<std::string>();
    if (image.file) {
      // A frame kept in tiles: read a band at a time from the open checkpoint.
      BufferFileBands bands("/proc/self/fd/" + std::to_string(image.file->fd), uint64_t(16) << 20);
      *png = encode_png(make_preview(bands, kPreviewSide));
    } else {
      SampleBuffer whole = decode_buffer(image.buffer, "frame " + std::to_string(frame));
      *png = encode_png(make_preview(WholeFrame(whole), kPreviewSide));
    }
    e->png = std::move(png);
    e->passes = image.status.progress.passes_merged;
    e->run = image.status.run;
    e->built_at = monotonic_seconds();
    ++previews_built;
    *built = true;
    return e->png;
  }

  void routes() {
    httplib::Server& s = *server;
    // In the open mode (no token file, loopback only) a page of any site could reach the port
    // by a name that resolves to 127.0.0.1 (DNS rebinding): only loopback Host names pass.
    s.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
      res.set_header("X-Content-Type-Options", "nosniff");
      res.set_header("X-Frame-Options", "DENY");
      res.set_header("Referrer-Policy", "no-referrer");
      if (o.open && !loopback_host(host_of(req.get_header_value("Host")))) {
        refuse(res, 403, "this monitor answers only to loopback host names");
        return httplib::Server::HandlerResponse::Handled;
      }
      return httplib::Server::HandlerResponse::Unhandled;
    });
    s.Get("/", [](const httplib::Request&, httplib::Response& res) {
      res.set_header("Content-Security-Policy",
                     "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' "
                     "data:; connect-src 'self'; form-action 'self'; frame-ancestors 'none'");
      res.set_header("Cache-Control", "no-store");
      res.set_content(kMonitorHtml, "text/html; charset=utf-8");
    });
    s.Get("/monitor.js", [](const httplib::Request&, httplib::Response& res) {
      res.set_content(kMonitorJs, "text/javascript; charset=utf-8");
    });
    s.Get("/monitor.css", [](const httplib::Request&, httplib::Response& res) {
      res.set_content(kMonitorCss, "text/css; charset=utf-8");
    });
    s.Post("/api/login", [this](const httplib::Request& req, httplib::Response& res) {
      if (!same_origin(req)) return refuse(res, 403, "cross-site request refused");
      std::string id;
      Session session;
      try {
        if (o.open) {
          session = new_session(Caller{}, true, now_unix() + int64_t(o.session_seconds), &id);
        } else {
          std::string token;
          try {
            token = nlohmann::json::parse(req.body).at("token").get<std::string>();
          } catch (const std::exception&) {
            return refuse(res, 400, "the body must be {\"token\": \"...\"}");
          }
          std::string why;
          std::optional<Principal> who = check(token, &why);
          if (!who) return refuse(res, 401, why);
          if (who->role == Role::Worker)
            return refuse(res, 403, "a worker token cannot log in: use a client or admin token");
          int64_t expires = now_unix() + int64_t(o.session_seconds);
          if (who->expires_unix) expires = std::min(expires, *who->expires_unix);
          const bool admin = who->role == Role::Admin;
          session = new_session(Caller{who->id, who->tenant, admin}, admin, expires, &id);
          spdlog::info("monitor: {} logged in from {}", who->id, req.remote_addr);
        }
      } catch (const CoordinatorError& e) {
        return refuse(res, http_status(e.code), e.what());
      }
      res.set_header("Set-Cookie", cookie(id, session.expires_unix - now_unix()));
      reply(res, 200, session_json(session));
    });
    s.Post("/api/logout", [this](const httplib::Request& req, httplib::Response& res) {
      api(req, res, [&](const Session& ses) {
        std::lock_guard lock(mu);
        for (auto it = sessions.begin(); it != sessions.end(); ++it)
          if (it->second.csrf == ses.csrf) {
            sessions.erase(it);
            break;
          }
        res.set_header("Set-Cookie", cookie("", 0));
        return nlohmann::json::object();
      });
    });
    s.Get("/api/session", [this](const httplib::Request& req, httplib::Response& res) {
      api(req, res, [&](const Session& ses) { return session_json(ses); });
    });
    s.Get("/api/jobs", [this](const httplib::Request& req, httplib::Response& res) {
      api(req, res, [&](const Session& ses) {
        const size_t limit = page_limit(req);
        const std::string after = req.get_param_value("after");
        bool more = false;
        std::vector<JobStatus> jobs = core.list(ses.caller, limit, after, &more);
        nlohmann::json list = nlohmann::json::array();
        for (const JobStatus& j : jobs) list.push_back(job_json(j));
        return nlohmann::json{
            {"jobs", std::move(list)},
            {"next_after", more && !jobs.empty() ? nlohmann::json(jobs.back().job_id) : nullptr}};
      });
    });
    s.Get(R"(/api/jobs/([A-Za-z0-9_.-]{1,64}))",
          [this](const httplib::Request& req, httplib::Response& res) {
            api(req, res, [&](const Session& ses) {
              // ?frames=N: the first N frames (default 1000, at most 100,000).
              size_t frames = 1000;
              if (req.has_param("frames")) {
                try {
                  frames = std::clamp<size_t>(std::stoul(req.get_param_value("frames")), 1, 100000);
                } catch (const std::exception&) {
                  throw CoordinatorError(ErrorCode::InvalidArgument, "frames: not a number");
                }
              }
              return job_json(core.status(req.matches[1], ses.caller), frames);
            });
          });
    s.Get(R"(/api/jobs/([A-Za-z0-9_.-]{1,64})/frames/(-?[0-9]{1,10})/preview\.png)",
          [this](const httplib::Request& req, httplib::Response& res) {
            std::optional<Session> ses = session_of(req);
            if (!ses) return refuse(res, 401, "no session: log in with a client token");
            try {
              bool built = false;
              std::shared_ptr<const std::string> png =
                  preview(ses->caller, req.matches[1], frame_of(req.matches[2]), &built);
              res.set_header("Cache-Control", "private, no-store");
              res.set_header("X-Rayfarm-Preview", built ? "built" : "cached");
              res.set_content(*png, "image/png");
            } catch (const CoordinatorError& e) {
              refuse(res, http_status(e.code), e.what());
            } catch (const std::exception& e) {
              refuse(res, 500, e.what());
            }
          });
    s.Get(R"(/api/jobs/([A-Za-z0-9_.-]{1,64})/frames/(-?[0-9]{1,10})/history)",
          [this](const httplib::Request& req, httplib::Response& res) {
            api(req, res, [&](const Session& ses) {
              const std::string id = req.matches[1];
              const FrameNumber frame = frame_of(req.matches[2]);
              const FrameHistory h = core.frame_history(id, frame, ses.caller);
              nlohmann::json points = nlohmann::json::array();
              for (const ProgressPoint& p : h.points)
                points.push_back(
                    {p.unix_time, p.passes,
                     p.passes >= 2 && p.rel_mse > 0 ? nlohmann::json(p.rel_mse) : nullptr});
              return nlohmann::json{
                  {"noise_target", h.noise_target > 0 ? nlohmann::json(h.noise_target) : nullptr},
                  {"points", std::move(points)}};
            });
          });
    s.Post(R"(/api/jobs/([A-Za-z0-9_.-]{1,64})/(cancel|pause|resume|retry))",
           [this](const httplib::Request& req, httplib::Response& res) {
             api(req, res, [&](const Session& ses) {
               const std::string id = req.matches[1], op = req.matches[2];
               if (op == "cancel")
                 core.cancel(id, ses.caller);
               else if (op == "pause" || op == "resume")
                 core.set_paused(id, op == "pause", ses.caller);
               else
                 core.retry(id, "", ses.caller);
               spdlog::info("monitor: {} {} job {}", ses.caller.principal, op, id);
               return job_json(core.status(id, ses.caller));
             });
           });
    s.Get("/api/workers", [this](const httplib::Request& req, httplib::Response& res) {
      api(req, res, [&](const Session& ses) {
        const size_t limit = page_limit(req);
        bool more = false;
        std::vector<WorkerStatus> page =
            core.workers(ses.caller, limit, req.get_param_value("after"), &more);
        nlohmann::json list = nlohmann::json::array();
        for (const WorkerStatus& w : page)
          list.push_back(
              {{"worker_id", w.worker_id},
               {"hostname", w.info.hostname},
               {"cores", w.info.cores},
               {"tags", w.info.tags},
               {"tasks", w.tasks},
               {"failures", w.failures},
               {"seconds_since_contact",
                w.seconds_since_contact >= 0 ? nlohmann::json(w.seconds_since_contact) : nullptr},
               {"refused", w.refused}});
        return nlohmann::json{
            {"workers", std::move(list)},
            {"next_after",
             more && !page.empty() ? nlohmann::json(page.back().worker_id) : nullptr}};
      });
    });
  }
};

Monitor::Monitor(Coordinator& core, const MonitorOptions& o, TokenCheck check)
    : impl_(std::make_unique<Impl>(core, o, std::move(check))) {
  const std::string host = host_of(o.listen);
  if (o.open && !loopback_host(host))
    throw std::runtime_error("coordinator: refusing --monitor-listen " + o.listen +
                             " without --token-file: anyone who reaches it could cancel jobs. "
                             "Give --token-file or listen on a loopback address (127.0.0.1:PORT)");
  if (o.tls_cert.empty()) {
    impl_->server = std::make_unique<httplib::Server>();
  } else {
    auto tls = std::make_unique<httplib::SSLServer>(o.tls_cert.c_str(), o.tls_key.c_str());
    if (!tls->is_valid())
      throw std::runtime_error("coordinator: --monitor-listen: cannot use --tls-cert " +
                               o.tls_cert + " and --tls-key " + o.tls_key);
    impl_->server = std::move(tls);
  }
  httplib::Server& s = *impl_->server;
  const int threads = o.threads;
  s.new_task_queue = [threads] { return new httplib::ThreadPool(size_t(threads)); };
  s.set_payload_max_length(64 * 1024);
  // An answer goes out as headers then body: without this, Nagle holds the body until the
  // client's delayed ACK (40 ms on Linux) on a kept-alive connection.
  s.set_tcp_nodelay(true);
  s.set_read_timeout(10, 0);
  s.set_write_timeout(10, 0);
  s.set_keep_alive_max_count(100);
  s.set_keep_alive_timeout(5);
  impl_->routes();
  const size_t colon = o.listen.rfind(':');
  if (colon == std::string::npos)
    throw std::runtime_error("coordinator: --monitor-listen " + o.listen + ": not HOST:PORT");
  int wanted = 0;
  try {
    wanted = std::stoi(o.listen.substr(colon + 1));
  } catch (const std::exception&) {
    throw std::runtime_error("coordinator: --monitor-listen " + o.listen + ": bad port");
  }
  impl_->port =
      wanted == 0 ? s.bind_to_any_port(host) : (s.bind_to_port(host, wanted) ? wanted : -1);
  if (impl_->port <= 0)
    throw std::runtime_error("coordinator: cannot listen on --monitor-listen " + o.listen);
  impl_->thread = std::thread([impl = impl_.get()] { impl->server->listen_after_bind(); });
}

Monitor::~Monitor() {
  impl_->server->stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

int Monitor::port() const { return impl_->port; }

void Monitor::revoke_sessions() {
  std::lock_guard lock(impl_->mu);
  impl_->sessions.clear();
}

uint64_t Monitor::previews_built() const { return impl_->previews_built.load(); }

size_t Monitor::sessions() const {
  std::lock_guard lock(impl_->mu);
  return impl_->sessions.size();
}

}  // namespace rf
