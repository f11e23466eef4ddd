// Worker tags and job requirements (docs/farm.md "Pools and tags"). A worker advertises tags:
// `name` or `name=value` (`gpu`, `pool=lighting`, `isa=x86_64-avx512`, `memory_gb=64`); a job may
// require some, each `name` (the worker has the tag), `name=value` (with that value) or
// `name>=number` (a numeric value at least that), and is leased only to workers meeting all of
// them. A job's pool is the value of its `pool=NAME` requirement: the autoscalers' unit.
#pragma once

#include <string>
#include <vector>

namespace rf {

inline constexpr size_t kMaxTags = 32;  // per worker and per job

// Why a tag (or a requirement) is not one, or "": a name of 1 to 64 of [a-z0-9_.-] starting with
// a letter; a value of 1 to 128 printable ASCII bytes, no space or comma.
std::string tag_problem(const std::string& tag);
std::string requirement_problem(const std::string& requirement);

// Whether the tags meet the requirement (which must be one: requirement_problem).
bool satisfies(const std::vector<std::string>& tags, const std::string& requirement);
bool satisfies_all(const std::vector<std::string>& tags,
                   const std::vector<std::string>& requirements);

// The value of the `pool=NAME` requirement, or "" (kAnyPool in the metrics) when there is none.
std::string pool_of(const std::vector<std::string>& requirements);
inline constexpr const char* kAnyPool = "any";

// The tags every worker advertises of itself: isa=<CPU kind> (engine/build_info.h, without an
// Embree configuration), cores=N (hardware threads), memory_gb=N (physical memory, rounded down).
std::vector<std::string> automatic_tags();

}  // namespace rf
