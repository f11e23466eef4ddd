#include "tests/support/exr.h"

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

namespace rf::test {

Exr read_exr(const std::string& path) {
  Exr e;
  auto in = OIIO::ImageInput::open(path);
  EXPECT_TRUE(in) << path;
  if (!in) return e;
  const OIIO::ImageSpec& spec = in->spec();
  e.w = spec.width, e.h = spec.height, e.nch = spec.nchannels;
  e.format = spec.format.c_str();
  e.names = spec.channelnames;
  for (const auto& p : spec.extra_attribs) e.attrs[p.name().string()] = p.get_string();
  e.px.resize(size_t(e.w) * e.h * e.nch);
  in->read_image(0, 0, 0, e.nch, OIIO::TypeDesc::FLOAT, e.px.data());
  return e;
}

}  // namespace rf::test
