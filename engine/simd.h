// SIMD over lanes without intrinsics: a loop over fixed-size lane arrays, compiled for several
// x86-64 levels (GCC's target_clones: AVX-512, AVX2, SSE4.2 and the baseline) with the best one
// picked when the program loads. Only for code whose every operation gives the same bits on each
// level: integer arithmetic and exact IEEE operations (no FMA contraction: -ffp-contract=off).
#pragma once

#include "engine/math.h"

// Flattened too: a loop vectorises only with every call in it inlined, and GCC's inliner, whose
// budget is per translation unit, can stop inlining one into a lane loop when other code is added
// to the unit, and the loop then runs scalar (docs/performance.md, "The path tracer's inner
// loop").
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define RF_SIMD_CLONES \
  [[gnu::flatten,      \
    gnu::target_clones("arch=x86-64-v4", "arch=x86-64-v3", "arch=x86-64-v2", "default")]]
#elif defined(__GNUC__)
#define RF_SIMD_CLONES [[gnu::flatten]]
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

namespace rf {

// What a loop over lanes works on: 3-vectors as lane arrays (a[axis][slot]), and a list of m
// slots (lane[0..m)) that hold work (the loops themselves run over all N slots: no scalar
// remainder).
template <int N_>
struct LaneSlots {
  static constexpr int N = N_;
  using V3 = float[3][N];
  static Vec3 get(const V3& a, int j) { return {a[0][j], a[1][j], a[2][j]}; }
  static void put(V3& a, int j, Vec3 v) { a[0][j] = v.x, a[1][j] = v.y, a[2][j] = v.z; }
  int m = 0;
  int lane[N];
};

}  // namespace rf
