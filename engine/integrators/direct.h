// Direct illumination (`direct`).
//
// Estimator: emitted radiance seen by the camera plus light that reaches the first surface
// straight from an emitter (exactly one scattering event, so it equals `path` with max depth 1).
// Strategy "light": N light samples (light chosen by power); "bsdf": M BSDF samples, emitters and
// the environment found along them; "mis": both, combined by the multi-sample MIS heuristic
// w_l = (N p_l)^b / ((N p_l)^b + (M p_f)^b), b = 2 (power) or 1 (balance) (Veach 1997, 9.2).
// Delta lights are reached by light sampling only and delta BSDFs by BSDF sampling only, both
// with weight 1, whatever the strategy, so the three strategies estimate the same image.
// Parameters: strategy, heuristic, light_samples N, bsdf_samples M.
// Strengths: the textbook test bed for importance sampling: light sampling wins for small lights
// on rough surfaces, BSDF sampling for big lights on glossy surfaces, MIS is never much worse than
// the better one.
// Cannot do: any indirect light.
#pragma once

#include <cstdint>
#include <string>

#include "engine/integrators/module.h"

namespace rf {

struct DirectIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "direct";
  static constexpr bool kSplats = false;
  static constexpr const char* kKeys[] = {"type", "strategy", "heuristic", "light_samples", "bsdf_samples"};

  static constexpr int kFixedMaxDepth = 1;  // direct lighting is exactly one bounce
  static constexpr const char* kMitsubaTypes = "direct";

  enum class Strategy : uint8_t { Light, Bsdf, Mis };  // values appear in settings_text
  Strategy strategy = Strategy::Mis;
  bool power_heuristic = true;  // MIS: power (true) or balance heuristic
  int light_samples = 1;        // N light samples per hit
  int bsdf_samples = 1;         // M BSDF samples per hit

  void parse(const JsonReader& r, const Json& j, const std::string& path);
  std::string settings_text() const;
  void from_mitsuba(const ForeignParams& p);  // shading_samples, emitter_samples, bsdf_samples

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const DirectIntegrator&) const = default;
};

}  // namespace rf
