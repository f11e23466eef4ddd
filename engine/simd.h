// SIMD over lanes without intrinsics: a loop over fixed-size lane arrays, compiled for several
// x86-64 levels (GCC's target_clones: AVX-512, AVX2, SSE4.2 and the baseline) with the best one
// picked when the program loads. Only for code whose every operation gives the same bits on each
// level: integer arithmetic and exact IEEE operations (no FMA contraction: -ffp-contract=off).
#pragma once

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define RF_SIMD_CLONES \
  [[gnu::target_clones("arch=x86-64-v4", "arch=x86-64-v3", "arch=x86-64-v2", "default")]]
#else
#define RF_SIMD_CLONES
#endif

// Before a loop whose iterations touch only their own elements of its arrays: GCC then vectorises
// it without run-time alias checks (which it gives up on past ten arrays).
#if defined(__GNUC__) && !defined(__clang__)
#define RF_IVDEP _Pragma("GCC ivdep")
#else
#define RF_IVDEP
#endif
