// Value conversions of the Mitsuba 3 importer (docs/formats/mitsuba.md): numbers and lists as
// Mitsuba writes them, named indices of refraction, conductor presets, and spectra to RGB.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "engine/math.h"

namespace rf::mitsuba {

// Parses a decimal number (the whole string, surrounding blanks allowed); nullopt if it is not one.
std::optional<double> parse_number(const std::string& text);
// Splits a list of numbers separated by commas and/or blanks ("1, 2 3"); nullopt naming nothing if
// an item is not a number (the caller reports it).
std::optional<std::vector<double>> parse_numbers(const std::string& text);

// Mitsuba's named indices of refraction ("bk7", "air", "water", ...): nullopt if unknown.
std::optional<float> named_ior(const std::string& name);
std::vector<std::string> named_ior_names();

// Mitsuba's conductor `material` names this importer maps to RGB eta/k (Au, Ag, Cu, Al and the
// engine's own preset names): nullptr-like nullopt if unknown.
struct ConductorIor {
  RGB eta, k;
};
std::optional<ConductorIor> conductor_material(const std::string& name);
std::vector<std::string> conductor_material_names();

// A sampled spectrum (wavelengths in nm, increasing) to linear sRGB: the piecewise-linear
// spectrum (zero outside the given range) is integrated against the CIE 1931 colour matching
// functions (Wyman, Sloan and Shirley 2013's analytic fit) over 360..830 nm, converted from XYZ to
// linear sRGB (D65 primaries) and divided per channel by the same conversion of the constant
// spectrum 1 (over 360..830 nm), so a flat spectrum becomes grey of its value: white-balanced to
// the equal-energy illuminant.
RGB spectrum_to_rgb(const std::vector<double>& wavelengths, const std::vector<double>& values);

}  // namespace rf::mitsuba
