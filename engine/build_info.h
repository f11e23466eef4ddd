// What made a result: the build id (version, git commit, compiler, build type) and the CPU's
// vector ISA that Embree dispatches to. Recorded in every buffer and image (DESIGN.md).
#pragma once

#include <string>

namespace rf {
const char* build_id();
std::string cpu_isa();  // e.g. "x86_64-avx2"
}  // namespace rf
