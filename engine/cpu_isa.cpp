#include "engine/build_info.h"

#include <cstdlib>

namespace rf {

namespace {
std::string cpu_kind() {
#if defined(__x86_64__)
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl"))
    return "x86_64-avx512";
  if (__builtin_cpu_supports("avx2")) return "x86_64-avx2";
  if (__builtin_cpu_supports("avx")) return "x86_64-avx";
  if (__builtin_cpu_supports("sse4.2")) return "x86_64-sse4.2";
  return "x86_64-sse2";
#elif defined(__aarch64__)
  return "aarch64-neon";
#else
  return "unknown";
#endif
}
}  // namespace

// With RAYFARM_EMBREE_CONFIG set (engine/accel.cpp), Embree may run another CPU kind's kernels,
// whose hits can differ in the last bits: the configuration is part of the kind (commas, which
// separate the kinds of a merged buffer, written as semicolons).
std::string cpu_isa() {
  const char* embree = std::getenv("RAYFARM_EMBREE_CONFIG");
  if (!embree || !*embree) return cpu_kind();
  std::string config = embree;
  for (char& c : config) c = c == ',' ? ';' : c;
  return cpu_kind() + " embree:" + config;
}

}  // namespace rf
