// Spectra as the engine's RGB, for the importers of spectral formats (pbrt-v4, Mitsuba 3): the
// CIE 1931 2-degree colour matching functions as the multi-lobe Gaussian fit of Wyman, Sloan and
// Shirley 2013 (JCGT 2(2), their equation 2; within about 1% of the tabulated peak), and CIE XYZ
// to linear sRGB (IEC 61966-2-1, Rec. 709 primaries, D65 white). The importers decide the
// normalisation (luminance 1 for emitters, a flat spectrum to grey for reflectances).
#pragma once

#include "engine/math.h"

namespace rf {

Vec3 cie_xyz(double nm);
RGB xyz_to_srgb(Vec3 xyz);

// The integral of f(nm) times the matching functions over 360..830 nm in 1 nm steps (CIE XYZ).
template <class F>
Vec3 integrate_xyz(F&& f) {
  double x = 0, y = 0, z = 0;
  for (int nm = 360; nm <= 830; ++nm) {
    double v = f(double(nm));
    Vec3 c = cie_xyz(nm);
    x += v * c.x, y += v * c.y, z += v * c.z;
  }
  return {float(x), float(y), float(z)};
}

}  // namespace rf
