#include "eval/png_plot.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

#if COVOX_HAVE_ZLIB
#include <zlib.h>
#endif

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"

namespace covox {
namespace eval {
namespace {

// 5x7 glyphs: seven rows, top first; bit 4 is the leftmost column.
struct Glyph {
  char character;
  std::array<uint8_t, 7> rows;
};

const Glyph kGlyphs[] = {
    {' ', {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}},
    {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}},
    {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}},
    {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}},
    {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}},
    {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'A', {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'B', {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}},
    {'C', {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E}},
    {'D', {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}},
    {'E', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F}},
    {'F', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}},
    {'G', {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F}},
    {'H', {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'I', {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'J', {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}},
    {'K', {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11}},
    {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}},
    {'M', {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11}},
    {'N', {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}},
    {'O', {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}},
    {'P', {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}},
    {'Q', {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D}},
    {'R', {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}},
    {'S', {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E}},
    {'T', {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}},
    {'U', {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}},
    {'V', {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}},
    {'W', {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A}},
    {'X', {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}},
    {'Y', {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04}},
    {'Z', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}},
    {'-', {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00}},
    {':', {0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00}},
    {'(', {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}},
    {')', {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08}},
    {'/', {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00}},
    {'_', {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F}},
    {'+', {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00}},
    {',', {0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08}},
    {'=', {0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00}},
    {'%', {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03}},
    {'?', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04}},
};

const std::array<uint8_t, 7>& glyph_rows(char c) {
  if (c >= 'a' && c <= 'z') c = static_cast<char>(c - 'a' + 'A');
  for (const Glyph& glyph : kGlyphs) {
    if (glyph.character == c) return glyph.rows;
  }
  return glyph_rows('?');
}

constexpr int kGlyphAdvance = 6;  // 5 columns and one of spacing
constexpr int kGlyphHeight = 7;

void append_u32_big_endian(std::vector<uint8_t>* bytes, uint32_t value) {
  for (int shift = 24; shift >= 0; shift -= 8)
    bytes->push_back(static_cast<uint8_t>(value >> shift));
}

void append_chunk(std::vector<uint8_t>* png, const char type[4], const std::vector<uint8_t>& data) {
  append_u32_big_endian(png, static_cast<uint32_t>(data.size()));
  const size_t type_start = png->size();
  png->insert(png->end(), type, type + 4);
  png->insert(png->end(), data.begin(), data.end());
  // The CRC covers the type and the data, not the length.
  append_u32_big_endian(png, crc32(png->data() + type_start, 4 + data.size()));
}

// ---------------------------------------------------------------------------------------------
// Plot geometry
// ---------------------------------------------------------------------------------------------

const Rgb kWhite{255, 255, 255};
const Rgb kBlack{0, 0, 0};
const Rgb kGrid{225, 225, 225};
const Rgb kFrame{90, 90, 90};

struct Range {
  double min = std::numeric_limits<double>::infinity();
  double max = -std::numeric_limits<double>::infinity();
  void add(double v) {
    if (!std::isfinite(v)) return;
    min = std::min(min, v);
    max = std::max(max, v);
  }
  bool valid() const { return min <= max; }
  double span() const { return max - min; }
};

// A 1-2-5 step giving roughly `target_ticks` ticks over `span`.
double nice_step(double span, int target_ticks) {
  const double raw = span / std::max(1, target_ticks);
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  for (double factor : {1.0, 2.0, 5.0}) {
    if (factor * magnitude >= raw) return factor * magnitude;
  }
  return 10.0 * magnitude;
}

std::string tick_label(double value, double step) {
  char text[32];
  // Enough decimals to tell neighbouring ticks apart, no more.
  const int decimals = step >= 1.0 ? 0 : static_cast<int>(std::ceil(-std::log10(step) - 1e-9));
  if (std::abs(value) < step * 1e-6) value = 0.0;  // no "-0"
  std::snprintf(text, sizeof(text), "%.*f", decimals, value);
  return text;
}

// Maps data coordinates into a pixel rectangle; y grows upwards in data, downwards in pixels.
struct Panel {
  int left = 0, top = 0, width = 0, height = 0;
  double x_min = 0, x_max = 1, y_min = 0, y_max = 1;
  int px(double x) const {
    return left + static_cast<int>(std::lround((x - x_min) / (x_max - x_min) * (width - 1)));
  }
  int py(double y) const {
    return top + height - 1 -
           static_cast<int>(std::lround((y - y_min) / (y_max - y_min) * (height - 1)));
  }
};

void draw_axes(RgbImage* image, const Panel& panel, const std::string& title) {
  const double x_step = nice_step(panel.x_max - panel.x_min, 8);
  const double y_step = nice_step(panel.y_max - panel.y_min, 6);
  for (double x = std::ceil(panel.x_min / x_step) * x_step; x <= panel.x_max + 1e-9 * x_step;
       x += x_step) {
    const int px = panel.px(x);
    image->draw_line(px, panel.top, px, panel.top + panel.height - 1, kGrid);
    const std::string label = tick_label(x, x_step);
    image->draw_text(px - RgbImage::text_width_px(label) / 2, panel.top + panel.height + 5, label,
                     kBlack);
  }
  for (double y = std::ceil(panel.y_min / y_step) * y_step; y <= panel.y_max + 1e-9 * y_step;
       y += y_step) {
    const int py = panel.py(y);
    image->draw_line(panel.left, py, panel.left + panel.width - 1, py, kGrid);
    const std::string label = tick_label(y, y_step);
    image->draw_text(panel.left - 6 - RgbImage::text_width_px(label), py - 3, label, kBlack);
  }
  const int right = panel.left + panel.width - 1;
  const int bottom = panel.top + panel.height - 1;
  image->draw_line(panel.left, panel.top, right, panel.top, kFrame);
  image->draw_line(panel.left, bottom, right, bottom, kFrame);
  image->draw_line(panel.left, panel.top, panel.left, bottom, kFrame);
  image->draw_line(right, panel.top, right, bottom, kFrame);
  image->draw_text(panel.left, panel.top - RgbImage::text_height_px(2) - 6, title, kBlack, 2);
}

void draw_series(RgbImage* image, const Panel& panel, const std::vector<PlotSeries>& series) {
  // Lines are clipped to the panel by drawing only segments whose ends are inside it: data ranges
  // are computed from the same points, so this only drops segments of non-finite points.
  for (const PlotSeries& s : series) {
    bool have_previous = false;
    int previous_x = 0, previous_y = 0;
    for (const PlotPoint& p : s.points) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y)) {
        have_previous = false;
        continue;
      }
      const int x = panel.px(p.x), y = panel.py(p.y);
      if (have_previous) image->draw_line(previous_x, previous_y, x, y, s.colour, 2);
      previous_x = x;
      previous_y = y;
      have_previous = true;
    }
  }
  // Legend in the top-left corner of the panel.
  int y = panel.top + 8;
  for (const PlotSeries& s : series) {
    image->fill_rect(panel.left + 8, y, 14, 7, s.colour);
    image->draw_text(panel.left + 28, y, s.label, kBlack);
    y += 12;
  }
}

Range x_range_of(const std::vector<PlotSeries>& series) {
  Range range;
  for (const PlotSeries& s : series)
    for (const PlotPoint& p : s.points) range.add(p.x);
  return range;
}

Range y_range_of(const std::vector<PlotSeries>& series) {
  Range range;
  for (const PlotSeries& s : series)
    for (const PlotPoint& p : s.points) range.add(p.y);
  return range;
}

// Pads a range by `fraction` of its span (and gives an empty or single-value range a width).
void pad(Range* range, double fraction) {
  if (!range->valid()) {
    range->min = 0.0;
    range->max = 1.0;
    return;
  }
  const double margin = range->span() > 0.0 ? fraction * range->span() : 0.5;
  range->min -= margin;
  range->max += margin;
}

}  // namespace

Rgb series_colour(size_t index) {
  // Okabe-Ito palette: distinguishable with the common colour-vision deficiencies.
  static const Rgb kPalette[] = {{0, 114, 178}, {213, 94, 0},   {0, 158, 115}, {204, 121, 167},
                                 {230, 159, 0}, {86, 180, 233}, {0, 0, 0},     {240, 228, 66}};
  return kPalette[index % (sizeof(kPalette) / sizeof(kPalette[0]))];
}

RgbImage::RgbImage(int width_px, int height_px, Rgb background)
    : width_px_(width_px), height_px_(height_px) {
  if (width_px <= 0 || height_px <= 0) {
    throw Error("image size must be positive, got " + std::to_string(width_px) + " x " +
                std::to_string(height_px));
  }
  rgb_bytes_.resize(static_cast<size_t>(width_px) * height_px * 3);
  for (size_t i = 0; i < rgb_bytes_.size(); i += 3) {
    rgb_bytes_[i] = background.r;
    rgb_bytes_[i + 1] = background.g;
    rgb_bytes_[i + 2] = background.b;
  }
}

void RgbImage::set_pixel(int x, int y, Rgb colour) {
  if (x < 0 || y < 0 || x >= width_px_ || y >= height_px_) return;
  const size_t i = (static_cast<size_t>(y) * width_px_ + x) * 3;
  rgb_bytes_[i] = colour.r;
  rgb_bytes_[i + 1] = colour.g;
  rgb_bytes_[i + 2] = colour.b;
}

Rgb RgbImage::pixel(int x, int y) const {
  if (x < 0 || y < 0 || x >= width_px_ || y >= height_px_) return Rgb();
  const size_t i = (static_cast<size_t>(y) * width_px_ + x) * 3;
  return Rgb{rgb_bytes_[i], rgb_bytes_[i + 1], rgb_bytes_[i + 2]};
}

void RgbImage::fill_rect(int x, int y, int width, int height, Rgb colour) {
  for (int row = std::max(0, y); row < std::min(height_px_, y + height); ++row)
    for (int column = std::max(0, x); column < std::min(width_px_, x + width); ++column)
      set_pixel(column, row, colour);
}

void RgbImage::draw_line(int x0, int y0, int x1, int y1, Rgb colour, int thickness_px) {
  const int dx = std::abs(x1 - x0), dy = -std::abs(y1 - y0);
  const int sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1;
  const int half = (thickness_px - 1) / 2;
  int error = dx + dy;
  while (true) {
    if (thickness_px <= 1)
      set_pixel(x0, y0, colour);
    else
      fill_rect(x0 - half, y0 - half, thickness_px, thickness_px, colour);
    if (x0 == x1 && y0 == y1) break;
    const int doubled = 2 * error;
    if (doubled >= dy) {
      error += dy;
      x0 += sx;
    }
    if (doubled <= dx) {
      error += dx;
      y0 += sy;
    }
  }
}

void RgbImage::draw_text(int x, int y, const std::string& text, Rgb colour, int scale) {
  for (size_t k = 0; k < text.size(); ++k) {
    const std::array<uint8_t, 7>& rows = glyph_rows(text[k]);
    const int glyph_x = x + static_cast<int>(k) * kGlyphAdvance * scale;
    for (int row = 0; row < kGlyphHeight; ++row) {
      for (int column = 0; column < 5; ++column) {
        if (rows[row] & (0x10 >> column)) {
          fill_rect(glyph_x + column * scale, y + row * scale, scale, scale, colour);
        }
      }
    }
  }
}

int RgbImage::text_width_px(const std::string& text, int scale) {
  if (text.empty()) return 0;
  return (static_cast<int>(text.size()) * kGlyphAdvance - 1) * scale;
}

int RgbImage::text_height_px(int scale) { return kGlyphHeight * scale; }

uint32_t crc32(const uint8_t* data, size_t size, uint32_t previous_crc) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> entries{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int bit = 0; bit < 8; ++bit) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      entries[n] = c;
    }
    return entries;
  }();
  uint32_t crc = previous_crc ^ 0xFFFFFFFFu;
  for (size_t i = 0; i < size; ++i) crc = table[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

uint32_t adler32(const uint8_t* data, size_t size) {
  constexpr uint32_t kModulus = 65521;
  uint32_t a = 1, b = 0;
  for (size_t i = 0; i < size; ++i) {
    a = (a + data[i]) % kModulus;
    b = (b + a) % kModulus;
  }
  return (b << 16) | a;
}

std::vector<uint8_t> zlib_stream(const std::vector<uint8_t>& raw) {
#if COVOX_HAVE_ZLIB
  uLongf size = compressBound(static_cast<uLong>(raw.size()));
  std::vector<uint8_t> compressed(size);
  if (compress2(compressed.data(), &size, raw.data(), static_cast<uLong>(raw.size()),
                Z_BEST_COMPRESSION) == Z_OK) {
    compressed.resize(size);
    return compressed;
  }
#endif
  // Header (deflate, 32 KiB window, no preset dictionary; 0x7801 is a multiple of 31 as the
  // header check requires), stored blocks of at most 65535 bytes, Adler-32 of the data.
  std::vector<uint8_t> zlib = {0x78, 0x01};
  constexpr size_t kMaxStored = 65535;
  size_t offset = 0;
  do {
    const size_t length = std::min(kMaxStored, raw.size() - offset);
    const bool last = offset + length == raw.size();
    zlib.push_back(last ? 1 : 0);  // BFINAL, BTYPE = 00 (stored)
    zlib.push_back(static_cast<uint8_t>(length & 0xFF));
    zlib.push_back(static_cast<uint8_t>(length >> 8));
    zlib.push_back(static_cast<uint8_t>(~length & 0xFF));
    zlib.push_back(static_cast<uint8_t>((~length >> 8) & 0xFF));
    zlib.insert(zlib.end(), raw.begin() + offset, raw.begin() + offset + length);
    offset += length;
  } while (offset < raw.size());
  append_u32_big_endian(&zlib, adler32(raw.data(), raw.size()));
  return zlib;
}

std::vector<uint8_t> png_scanlines(const RgbImage& image) {
  const size_t row_bytes = static_cast<size_t>(image.width_px()) * 3;
  // Scanlines, each preceded by its filter type (0: none).
  std::vector<uint8_t> raw;
  raw.reserve((row_bytes + 1) * image.height_px());
  for (int y = 0; y < image.height_px(); ++y) {
    raw.push_back(0);
    const uint8_t* row = image.rgb_bytes().data() + y * row_bytes;
    raw.insert(raw.end(), row, row + row_bytes);
  }
  return raw;
}

std::vector<uint8_t> encode_png(const RgbImage& image) {
  const std::vector<uint8_t> zlib = zlib_stream(png_scanlines(image));
  std::vector<uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  std::vector<uint8_t> header;
  append_u32_big_endian(&header, static_cast<uint32_t>(image.width_px()));
  append_u32_big_endian(&header, static_cast<uint32_t>(image.height_px()));
  header.insert(header.end(), {8, 2, 0, 0, 0});  // 8 bits, RGB, deflate, filter 0, no interlace
  append_chunk(&png, "IHDR", header);
  append_chunk(&png, "IDAT", zlib);
  append_chunk(&png, "IEND", {});
  return png;
}

void write_png(const std::string& path, const RgbImage& image) {
  const std::vector<uint8_t> bytes = encode_png(image);
  io::write_file_replacing(path, "PNG plot", /*binary=*/true, [&](std::ostream& file) {
    file.write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  });
}

RgbImage render_trajectory_figure(const TrajectoryFigure& figure, int width_px) {
  if (width_px < 300) throw Error("trajectory figure: width must be at least 300 px");
  const int margin_left = 70, margin_right = 20, title_space = 36, label_space = 24;
  const int panel_width = width_px - margin_left - margin_right;

  // Top view: equal scales on x and y, so the panel height follows the data's aspect ratio.
  Range x = x_range_of(figure.top_view_m), y = y_range_of(figure.top_view_m);
  pad(&x, 0.05);
  pad(&y, 0.05);
  const double aspect = std::clamp(y.span() / x.span(), 0.3, 1.5);
  const int top_height = static_cast<int>(panel_width * aspect);
  const int error_height = std::max(150, width_px / 4);
  const int height_px =
      title_space + top_height + label_space + title_space + error_height + label_space + 10;
  RgbImage image(width_px, height_px, kWhite);

  Panel top;
  top.left = margin_left;
  top.top = title_space;
  top.width = panel_width;
  top.height = top_height;
  // Widen whichever axis is short so one metre is the same number of pixels on both.
  const double metres_per_px = std::max(x.span() / panel_width, y.span() / top_height);
  const double x_centre = 0.5 * (x.min + x.max), y_centre = 0.5 * (y.min + y.max);
  top.x_min = x_centre - 0.5 * metres_per_px * panel_width;
  top.x_max = x_centre + 0.5 * metres_per_px * panel_width;
  top.y_min = y_centre - 0.5 * metres_per_px * top_height;
  top.y_max = y_centre + 0.5 * metres_per_px * top_height;
  draw_axes(&image, top, figure.top_view_title);
  draw_series(&image, top, figure.top_view_m);

  Range t = x_range_of(figure.error_over_time), e = y_range_of(figure.error_over_time);
  pad(&t, 0.0);
  if (!e.valid()) e.max = 1.0;
  e.min = 0.0;  // errors are non-negative; start the axis at zero so magnitudes read honestly
  e.max = e.max > 0.0 ? 1.1 * e.max : 1.0;
  Panel error;
  error.left = margin_left;
  error.top = top.top + top_height + label_space + title_space;
  error.width = panel_width;
  error.height = error_height;
  error.x_min = t.min;
  error.x_max = t.max;
  error.y_min = e.min;
  error.y_max = e.max;
  draw_axes(&image, error, figure.error_title);
  draw_series(&image, error, figure.error_over_time);
  return image;
}

RgbImage render_stacked_panels(const std::vector<PlotPanel>& panels, int width_px,
                               int panel_height_px) {
  if (panels.empty()) throw Error("stacked panels: nothing to draw");
  if (width_px < 300) throw Error("stacked panels: width must be at least 300 px");
  if (panel_height_px < 100) throw Error("stacked panels: panel height must be at least 100 px");
  const int margin_left = 70, margin_right = 20, title_space = 36, label_space = 24;
  // One x range over every panel, so that a time on one panel lies above the same time below.
  Range x;
  for (const PlotPanel& panel : panels) {
    const Range own = x_range_of(panel.series);
    if (own.valid()) {
      x.add(own.min);
      x.add(own.max);
    }
  }
  pad(&x, 0.0);
  const int block_px = title_space + panel_height_px + label_space;
  RgbImage image(width_px, block_px * static_cast<int>(panels.size()) + 10, kWhite);
  for (size_t k = 0; k < panels.size(); ++k) {
    Range y = y_range_of(panels[k].series);
    // Memory and latency are non-negative: the axis starts at zero so magnitudes read honestly.
    const double top_value = y.valid() && y.max > 0.0 ? 1.1 * y.max : 1.0;
    Panel frame;
    frame.left = margin_left;
    frame.top = static_cast<int>(k) * block_px + title_space;
    frame.width = width_px - margin_left - margin_right;
    frame.height = panel_height_px;
    frame.x_min = x.min;
    frame.x_max = x.max;
    frame.y_min = 0.0;
    frame.y_max = top_value;
    draw_axes(&image, frame, panels[k].title);
    draw_series(&image, frame, panels[k].series);
  }
  return image;
}

}  // namespace eval
}  // namespace covox
