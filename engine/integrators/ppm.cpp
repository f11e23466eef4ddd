// Placeholder until progressive photon mapping lands: "ppm" is not in known_integrators().
#include <stdexcept>

#include "engine/integrator.h"

namespace rf {
struct PhotonMap {};
std::shared_ptr<const PhotonMap> build_photon_map(const RenderContext&, uint32_t, TraceCounters&) {
  throw std::logic_error("ppm is not implemented yet");
}
RGB ppm_radiance(const RenderContext&, const PhotonMap&, Ray, Sampler&, TraceCounters&) {
  throw std::logic_error("ppm is not implemented yet");
}
}  // namespace rf
