#include "engine/build_info.h"

namespace rf {

std::string cpu_isa() {
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

}  // namespace rf
