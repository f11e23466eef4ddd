// Log lines of the services (coordinator, worker): --log-level and --log-format (text or JSON
// lines), for a cluster's log collector.
#include <spdlog/pattern_formatter.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <ctime>
#include <nlohmann/json.hpp>

#include "cli/commands.h"

namespace rf::cli {

namespace {

// One JSON object a line: {"time": "2026-12-07T13:00:00.123Z", "level": "info", "msg": "..."},
// the message escaped (invalid UTF-8 replaced), so a collector never sees a broken line.
class JsonLineFormatter : public spdlog::formatter {
 public:
  void format(const spdlog::details::log_msg& msg, spdlog::memory_buf_t& dest) override {
    using namespace std::chrono;
    const auto t = msg.time;
    const std::time_t secs = system_clock::to_time_t(t);
    const auto ms = duration_cast<milliseconds>(t.time_since_epoch()).count() % 1000;
    std::tm utc{};
    gmtime_r(&secs, &utc);
    char when[40];
    std::snprintf(when, sizeof when, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", utc.tm_year + 1900,
                  utc.tm_mon + 1, utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec, int(ms));
    const auto level = spdlog::level::to_string_view(msg.level);
    nlohmann::json line = {{"time", when},
                           {"level", std::string(level.data(), level.size())},
                           {"msg", std::string(msg.payload.data(), msg.payload.size())}};
    const std::string text =
        line.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
    dest.append(text.data(), text.data() + text.size());
  }
  std::unique_ptr<spdlog::formatter> clone() const override {
    return std::make_unique<JsonLineFormatter>();
  }
};

}  // namespace

std::shared_ptr<LogOptions> add_log_options(CLI::App* c) {
  auto log = std::make_shared<LogOptions>();
  c->add_option("--log-level", log->level,
                "the least severe lines logged: trace, debug, info (default), warn, error, off")
      ->envname("RAYFARM_LOG_LEVEL")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "critical", "off"}));
  c->add_option("--log-format", log->format,
                "text (default), or json: one JSON object a line (time, level, msg) on stderr")
      ->envname("RAYFARM_LOG_FORMAT")
      ->check(CLI::IsMember({"text", "json"}));
  return log;
}

void configure_logging(const LogOptions& log, bool long_running) {
  spdlog::set_level(spdlog::level::from_str(log.level));
  if (log.format == "json")
    spdlog::set_formatter(std::make_unique<JsonLineFormatter>());
  else
    spdlog::set_pattern(long_running ? "[%Y-%m-%d %H:%M:%S.%e] %^%l%$: %v" : "%^%l%$: %v");
}

}  // namespace rf::cli
