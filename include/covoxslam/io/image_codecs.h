#pragma once
// Decoding the image files of the RGB-D datasets: 16-bit grey PNG depth images and 8-bit colour
// PNG / JPEG images. libpng and libjpeg are optional at build time; without one, reading that
// format throws covox::NotAvailableError saying which library to install.
#include <cstdint>
#include <string>
#include <vector>

#include "covoxslam/io/sensor_data.h"

namespace covox {
namespace io {

// Row-major 16-bit single-channel image (raw depth units, as the file stores them).
struct Gray16Image {
  int width = 0;
  int height = 0;
  std::vector<uint16_t> pixels;

  uint16_t at(int row, int column) const {
    return pixels[static_cast<size_t>(row) * width + column];
  }
};

struct ImageSize {
  int width = 0;
  int height = 0;
};

bool png_reader_available();
bool jpeg_reader_available();

// Reads a 16-bit greyscale PNG (depth images). Throws covox::Error naming the file when it is
// not a PNG, not 16-bit grey, or corrupt.
Gray16Image read_png_gray16(const std::string& path);

// Reads a colour image as 8-bit RGB, PNG or JPEG decided by the file's first bytes (not its
// name). Grey, palette, 16-bit and alpha PNGs are converted (alpha dropped).
ColorImage read_color_image(const std::string& path);

// Width and height of a PNG from its header alone (no decoding, no libpng needed): lets a
// dataset reader learn the image size without decoding a frame.
ImageSize read_png_size(const std::string& path);

}  // namespace io
}  // namespace covox
