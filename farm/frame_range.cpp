#include "farm/frame_range.h"

#include <algorithm>
#include <charconv>
#include <set>

namespace rf {

namespace {

int64_t parse_int(const std::string& s, const std::string& item, const char* what) {
  int64_t v = 0;
  const char* end = s.data() + s.size();
  auto [p, ec] = std::from_chars(s.data(), end, v);
  if (s.empty() || ec != std::errc() || p != end)
    throw FrameRangeError("frame range item '" + item + "': " + what + " '" + s +
                          "' is not an integer");
  return v;
}

// Splits "A-B" where A may itself be negative ("-5-3"): the separator is the first '-' after
// the first character.
bool split_range(const std::string& s, std::string& a, std::string& b) {
  size_t dash = s.find('-', 1);
  if (dash == std::string::npos) return false;
  a = s.substr(0, dash);
  b = s.substr(dash + 1);
  return true;
}

}  // namespace

std::string frame_range_text(std::vector<FrameNumber> frames) {
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  std::string out;
  for (size_t i = 0; i < frames.size();) {
    size_t j = i;
    while (j + 1 < frames.size() && int64_t(frames[j + 1]) == int64_t(frames[j]) + 1) ++j;
    if (!out.empty()) out += ',';
    out += std::to_string(frames[i]);
    if (j > i) out += '-' + std::to_string(frames[j]);
    i = j + 1;
  }
  return out;
}

std::vector<FrameNumber> parse_frame_range(const std::string& text) {
  std::vector<FrameNumber> frames;
  std::set<FrameNumber> seen;
  if (text.find_first_not_of(" \t") == std::string::npos)
    throw FrameRangeError("frame range is empty");
  size_t start = 0;
  while (start <= text.size()) {
    size_t comma = text.find(',', start);
    std::string item =
        text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    start = comma == std::string::npos ? text.size() + 1 : comma + 1;
    // Spaces around items and separators are allowed.
    std::string s;
    for (char c : item)
      if (c != ' ' && c != '\t') s.push_back(c);
    if (s.empty()) throw FrameRangeError("frame range '" + text + "' has an empty item");
    std::string range = s, step_text;
    if (size_t colon = s.find(':'); colon != std::string::npos) {
      range = s.substr(0, colon);
      step_text = s.substr(colon + 1);
    }
    std::string a, b;
    int64_t first, last, step = 1;
    if (split_range(range, a, b)) {
      first = parse_int(a, item, "start");
      last = parse_int(b, item, "end");
      step = step_text.empty() ? (last >= first ? 1 : -1) : parse_int(step_text, item, "step");
    } else {
      if (!step_text.empty())
        throw FrameRangeError("frame range item '" + item + "': a step needs a range");
      first = last = parse_int(range, item, "frame");
    }
    if (step == 0) throw FrameRangeError("frame range item '" + item + "': step must not be 0");
    if ((last - first) * step < 0)
      throw FrameRangeError("frame range item '" + item + "': step " + std::to_string(step) +
                            " goes away from the end");
    if (std::min(first, last) < kMinFrame || std::max(first, last) > kMaxFrame)
      throw FrameRangeError("frame range item '" + item + "': frame number out of range (" +
                            std::to_string(kMinFrame) + " to " + std::to_string(kMaxFrame) + ")");
    for (int64_t f = first; step > 0 ? f <= last : f >= last; f += step) {
      if (frames.size() >= kMaxFrames)
        throw FrameRangeError("frame range has more than " + std::to_string(kMaxFrames) +
                              " frames");
      if (!seen.insert(FrameNumber(f)).second)
        throw FrameRangeError("frame range item '" + item + "': frame " + std::to_string(f) +
                              " is listed twice");
      frames.push_back(FrameNumber(f));
    }
  }
  return frames;
}

namespace {
// The length of a printf-style frame field at pattern[i] ('%d', '%0Nd'; 0 when there is none) and
// its zero-padded width.
size_t printf_field(const std::string& pattern, size_t i, size_t& width) {
  if (pattern[i] != '%' || i + 1 >= pattern.size()) return 0;
  if (pattern[i + 1] == 'd') {
    width = 0;
    return 2;
  }
  if (pattern[i + 1] != '0') return 0;
  size_t j = i + 2, w = 0;
  while (j < pattern.size() && j < i + 4 && pattern[j] >= '0' && pattern[j] <= '9')
    w = 10 * w + size_t(pattern[j++] - '0');
  if (j == i + 2 || j >= pattern.size() || pattern[j] != 'd' || w < 1 || w > 10) return 0;
  width = w;
  return j + 1 - i;
}

// As printf's "%0*d": a negative frame's sign counts in the width ("-07" for -7 at width 3).
std::string padded(FrameNumber frame, size_t width) {
  std::string digits = std::to_string(frame < 0 ? -int64_t(frame) : int64_t(frame));
  size_t sign = frame < 0 ? 1 : 0;
  if (digits.size() + sign < width) digits.insert(0, width - digits.size() - sign, '0');
  return frame < 0 ? "-" + digits : digits;
}
}  // namespace

std::string expand_frame_pattern(const std::string& pattern, FrameNumber frame, bool printf_style) {
  std::string out;
  for (size_t i = 0; i < pattern.size();) {
    size_t width = 0;
    if (pattern[i] == '#') {
      size_t n = 0;
      while (i + n < pattern.size() && pattern[i + n] == '#') ++n;
      out += padded(frame, n);
      i += n;
    } else if (printf_style && pattern.compare(i, 2, "%%") == 0) {
      out += '%';
      i += 2;
    } else if (size_t n = printf_style ? printf_field(pattern, i, width) : 0; n > 0) {
      out += padded(frame, width);
      i += n;
    } else {
      out += pattern[i++];
    }
  }
  return out;
}

bool is_frame_pattern(const std::string& pattern, bool printf_style) {
  return expand_frame_pattern(pattern, 0, printf_style) !=
         expand_frame_pattern(pattern, 1, printf_style);
}

}  // namespace rf
