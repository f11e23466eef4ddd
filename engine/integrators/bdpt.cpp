// Placeholder until the bidirectional path tracer lands: "bdpt" is not in known_integrators(),
// so no scene can select it.
#include <stdexcept>

#include "engine/integrator.h"

namespace rf {
RGB bdpt_sample(const RenderContext&, const PerspectiveCamera&, Ray, Sampler&, SplatTarget&,
                TraceCounters&) {
  throw std::logic_error("bdpt is not implemented yet");
}
}  // namespace rf
