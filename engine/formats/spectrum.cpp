#include "engine/formats/spectrum.h"

#include <cmath>

namespace rf {

namespace {

// One lobe of the fit: a Gaussian with different widths left and right of its peak.
double lobe(double nm, double mu, double sigma_left, double sigma_right) {
  double t = (nm - mu) / (nm < mu ? sigma_left : sigma_right);
  return std::exp(-0.5 * t * t);
}

}  // namespace

Vec3 cie_xyz(double nm) {
  double x = 1.056 * lobe(nm, 599.8, 37.9, 31.0) + 0.362 * lobe(nm, 442.0, 16.0, 26.7) -
             0.065 * lobe(nm, 501.1, 20.4, 26.2);
  double y = 0.821 * lobe(nm, 568.8, 46.9, 40.5) + 0.286 * lobe(nm, 530.9, 16.3, 31.1);
  double z = 1.217 * lobe(nm, 437.0, 11.8, 36.0) + 0.681 * lobe(nm, 459.0, 26.0, 13.8);
  return {float(x), float(y), float(z)};
}

RGB xyz_to_srgb(Vec3 c) {
  return {3.2404542f * c.x - 1.5371385f * c.y - 0.4985314f * c.z,
          -0.9692660f * c.x + 1.8760108f * c.y + 0.0415560f * c.z,
          0.0556434f * c.x - 0.2040259f * c.y + 1.0572252f * c.z};
}

}  // namespace rf
