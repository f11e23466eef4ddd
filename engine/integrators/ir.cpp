// Placeholder until instant radiosity lands: "ir" is not in known_integrators().
#include <stdexcept>

#include "engine/integrator.h"

namespace rf {
struct VplSet {};
std::shared_ptr<const VplSet> build_vpls(const RenderContext&, uint32_t, TraceCounters&) {
  throw std::logic_error("ir is not implemented yet");
}
RGB ir_radiance(const RenderContext&, const VplSet&, Ray, Sampler&, TraceCounters&) {
  throw std::logic_error("ir is not implemented yet");
}
}  // namespace rf
