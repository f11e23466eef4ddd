// Dispatch of a task to the integrator's estimator (registry.h); the renderer's half of the
// registry. The scene layer's half (names, parsing, settings text) is settings.cpp.
#include "engine/integrators/registry.h"

#include "engine/integrators/common.h"
#include "engine/sample_buffer.h"
#include "engine/scene.h"

namespace rf {

SampleBuffer render_task(const RenderContext& ctx, const TaskKey& task, bool parallel) {
  return std::visit(
      [&](const auto& integrator) { return integrator.render(ctx, task, parallel); },
      ctx.scene.render.integrator.method);
}

}  // namespace rf
