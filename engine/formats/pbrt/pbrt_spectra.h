// pbrt-v4's spectra as the engine's RGB (docs/formats/pbrt.md "Colour").
//
// pbrt-v4 renders spectrally; rayfarm renders linear sRGB (Rec. 709 primaries, D65 white).
// - "rgb" values are used as they are: an RGB reflectance is pbrt's RGBAlbedoSpectrum, and an RGB
//   emission is an RGBIlluminantSpectrum (the RGB times the colour space's D65, divided by D65's
//   luminance), which an sRGB film renders back to the same RGB.
// - Sampled spectra ("spectrum" [lambda value ...]) and blackbodies go through the CIE 1931
//   matching functions to XYZ, then to linear sRGB (engine/formats/spectrum.h). Emission spectra are normalised to luminance Y = 1 first, as pbrt-v4's lights
//   do (scale /= SpectrumToPhotometric); reflectance spectra are divided per channel by the RGB of
//   the constant spectrum 1, so a flat spectrum c gives grey (c, c, c).
// - Named spectra: "metal-{Au,Ag,Cu,Al}-{eta,k}" are the engine's conductor presets (gold, silver,
//   copper, aluminium); "glass-*" are the Schott glasses' index at the d line (587.6 nm);
//   "stdillum-D65" is white (1, 1, 1), "stdillum-A" a 2856 K blackbody.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "engine/math.h"

namespace rf::pbrt {

// Planck's law at temperature kelvin, normalised to luminance 1, as linear sRGB; negative
// components (very low or very high temperatures lie outside sRGB) are clamped to 0.
RGB blackbody_rgb(double kelvin);

// A piecewise-linear spectrum given as (lambda nm, value) pairs, lambda increasing.
// illuminant: normalised to luminance 1 (pbrt-v4's lights); else a reflectance (see above).
RGB sampled_spectrum_rgb(const std::vector<double>& pairs, bool illuminant);

// A named spectrum as RGB (nullopt if unknown). `illuminant` as above.
std::optional<RGB> named_spectrum_rgb(const std::string& name, bool illuminant);
// The index of refraction of a named glass ("glass-BK7", ...), nullopt if unknown.
std::optional<float> named_glass_ior(const std::string& name);
// Every name the two functions above know (for messages).
std::vector<std::string> known_spectrum_names();

}  // namespace rf::pbrt
