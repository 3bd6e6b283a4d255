#pragma once
// Plots as PNG files with no image library: an RGB canvas with Bresenham lines and a built-in
// 5x7 pixel font, and a minimal PNG encoder (zlib stream of stored deflate blocks, so no
// compressor is needed; CRC-32 and Adler-32 computed here). The files are larger than a
// compressed PNG would be (3 bytes per pixel) but every viewer opens them, and the tools stay
// free of dependencies that the Jetson and GPU images may not have.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace covox {
namespace eval {

struct Rgb {
  uint8_t r = 0;
  uint8_t g = 0;
  uint8_t b = 0;
};

inline bool operator==(const Rgb& a, const Rgb& b) {
  return a.r == b.r && a.g == b.g && a.b == b.b;
}

// Distinct, colour-blind-friendly colours for series 0, 1, 2, ... (cycling).
Rgb series_colour(size_t index);

class RgbImage {
 public:
  RgbImage(int width_px, int height_px, Rgb background);

  int width_px() const { return width_px_; }
  int height_px() const { return height_px_; }
  // Row-major, 3 bytes per pixel, top row first (the PNG scanline order).
  const std::vector<uint8_t>& rgb_bytes() const { return rgb_bytes_; }

  // Drawing outside the image is silently clipped: plots clip lines at their frame.
  void set_pixel(int x, int y, Rgb colour);
  Rgb pixel(int x, int y) const;
  void fill_rect(int x, int y, int width, int height, Rgb colour);
  // Bresenham; thickness_px > 1 stamps a square of that size at every step.
  void draw_line(int x0, int y0, int x1, int y1, Rgb colour, int thickness_px = 1);
  // Upper-case letters, digits and . - : ( ) / _ + , = % ? (lower case is drawn as upper case,
  // anything else as '?'). `scale` multiplies the 5x7 glyphs; (x, y) is the top-left corner.
  void draw_text(int x, int y, const std::string& text, Rgb colour, int scale = 1);
  static int text_width_px(const std::string& text, int scale = 1);
  static int text_height_px(int scale = 1);

 private:
  int width_px_;
  int height_px_;
  std::vector<uint8_t> rgb_bytes_;
};

// CRC-32 as PNG and zlib define it (polynomial 0xEDB88320). Pass the previous result as
// `previous_crc` to continue over several buffers.
uint32_t crc32(const uint8_t* data, size_t size, uint32_t previous_crc = 0);
// Adler-32 as zlib defines it (starts at 1).
uint32_t adler32(const uint8_t* data, size_t size);

// The image data a PNG compresses: each row preceded by its filter type, 0 (none).
std::vector<uint8_t> png_scanlines(const RgbImage& image);
// A zlib stream of `raw`: zlib's deflate where the build has zlib (COVOX_HAVE_ZLIB), else
// stored blocks.
std::vector<uint8_t> zlib_stream(const std::vector<uint8_t>& raw);
// The complete PNG file: 8-bit RGB, no interlace, filter type 0 (none) on every row.
std::vector<uint8_t> encode_png(const RgbImage& image);
// Throws covox::Error when the file cannot be written.
void write_png(const std::string& path, const RgbImage& image);

// ---------------------------------------------------------------------------------------------
// The trajectory figure: top view (x-y, equal axis scales) above the error over time.
// ---------------------------------------------------------------------------------------------

struct PlotPoint {
  double x = 0.0;
  double y = 0.0;
};

struct PlotSeries {
  std::string label;
  Rgb colour;
  std::vector<PlotPoint> points;  // drawn as a polyline; non-finite points break the line
};

struct TrajectoryFigure {
  std::vector<PlotSeries> top_view_m;       // x, y in metres
  std::vector<PlotSeries> error_over_time;  // time in s, error in m
  std::string top_view_title = "TOP VIEW X-Y (M)";
  std::string error_title = "POSITION ERROR (M) OVER TIME (S)";
};

RgbImage render_trajectory_figure(const TrajectoryFigure& figure, int width_px = 1000);

// ---------------------------------------------------------------------------------------------
// Panels stacked top to bottom that share the x axis (e.g. a mission timeline: memory above
// latency against mission time), each with its own y range starting at zero.
// ---------------------------------------------------------------------------------------------

struct PlotPanel {
  std::string title;
  std::vector<PlotSeries> series;
};

// Throws covox::Error when there is no panel or the width is below 300 px.
RgbImage render_stacked_panels(const std::vector<PlotPanel>& panels, int width_px = 1000,
                               int panel_height_px = 220);

}  // namespace eval
}  // namespace covox
