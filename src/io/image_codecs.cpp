#include "covoxslam/io/image_codecs.h"

#include <cstdio>
#include <cstring>
#include <memory>

#include "covoxslam/core/error.h"
#include "covoxslam/io/file_bytes.h"

#if COVOX_HAVE_PNG
#include <png.h>
#endif
#if COVOX_HAVE_JPEG
// jpeglib.h needs size_t and FILE declared first.
#include <csetjmp>
#include <jpeglib.h>
#include <jerror.h>  // JWRN_JPEG_EOF
#endif

namespace covox {
namespace io {
namespace {

constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
constexpr uint8_t kJpegSignature[3] = {0xff, 0xd8, 0xff};
// Dataset images are at most a few thousand pixels wide; a header claiming more is corrupt and
// would otherwise make us allocate gigabytes before failing.
constexpr uint32_t kMaxImageSide = 1 << 15;

bool starts_with(const std::vector<uint8_t>& bytes, const uint8_t* signature, size_t length) {
  return bytes.size() >= length && std::memcmp(bytes.data(), signature, length) == 0;
}

[[maybe_unused]] void check_size(uint32_t width, uint32_t height, const std::string& path) {
  if (width == 0 || height == 0 || width > kMaxImageSide || height > kMaxImageSide) {
    throw Error("'" + path + "': image size " + std::to_string(width) + " x " +
                std::to_string(height) + " is empty or implausibly large: corrupt header");
  }
}

#if COVOX_HAVE_PNG

// libpng reports errors by longjmp. The decoding below keeps only trivially destructible locals
// in the frames a longjmp can skip, and everything with a destructor (the output vectors, the
// libpng handles) lives in the caller, so no destructor is ever skipped.
struct PngSource {
  const uint8_t* data = nullptr;
  size_t size = 0;
  size_t position = 0;
  char message[256] = {};
};

void png_read_from_memory(png_structp png, png_bytep out, png_size_t length) {
  auto* source = static_cast<PngSource*>(png_get_io_ptr(png));
  if (length > source->size - source->position) png_error(png, "file is truncated");
  std::memcpy(out, source->data + source->position, length);
  source->position += length;
}

void png_record_error(png_structp png, png_const_charp message) {
  auto* source = static_cast<PngSource*>(png_get_error_ptr(png));
  std::snprintf(source->message, sizeof(source->message), "%s", message);
  png_longjmp(png, 1);
}

void png_ignore_warning(png_structp, png_const_charp) {
  // Warnings are about ancillary chunks (colour profiles, text) that the readers do not use.
}

struct PngHandles {
  png_structp png = nullptr;
  png_infop info = nullptr;
  ~PngHandles() {
    if (png != nullptr) png_destroy_read_struct(&png, info != nullptr ? &info : nullptr, nullptr);
  }
};

enum class PngTarget { kGray16, kRgb8 };

// What the decoder found; filled before any pixel is read so the caller can size its buffers.
struct PngLayout {
  uint32_t width = 0;
  uint32_t height = 0;
  int bit_depth = 0;
  int color_type = 0;
  size_t row_bytes = 0;
};

// Reads the header and sets up the conversion to `target`. Returns false on a libpng error
// (message in source.message).
bool png_start(PngHandles& handles, PngSource& source, PngTarget target, PngLayout* layout) {
  if (setjmp(png_jmpbuf(handles.png))) return false;
  png_set_read_fn(handles.png, &source, png_read_from_memory);
  png_read_info(handles.png, handles.info);
  layout->width = png_get_image_width(handles.png, handles.info);
  layout->height = png_get_image_height(handles.png, handles.info);
  layout->bit_depth = png_get_bit_depth(handles.png, handles.info);
  layout->color_type = png_get_color_type(handles.png, handles.info);
  if (target == PngTarget::kGray16) {
    if (layout->bit_depth != 16 || layout->color_type != PNG_COLOR_TYPE_GRAY)
      return true;              // caller rejects
    png_set_swap(handles.png);  // PNG stores 16-bit samples big-endian; our hosts are little-endian
  } else {
    if (layout->color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(handles.png);
    if (layout->color_type == PNG_COLOR_TYPE_GRAY && layout->bit_depth < 8) {
      png_set_expand_gray_1_2_4_to_8(handles.png);
    }
    if (layout->bit_depth == 16) png_set_strip_16(handles.png);
    if (layout->color_type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(handles.png);
    if (layout->color_type == PNG_COLOR_TYPE_GRAY ||
        layout->color_type == PNG_COLOR_TYPE_GRAY_ALPHA) {
      png_set_gray_to_rgb(handles.png);
    }
  }
  png_set_interlace_handling(handles.png);
  png_read_update_info(handles.png, handles.info);
  layout->row_bytes = png_get_rowbytes(handles.png, handles.info);
  return true;
}

bool png_finish(PngHandles& handles, png_bytep* rows) {
  if (setjmp(png_jmpbuf(handles.png))) return false;
  png_read_image(handles.png, rows);
  png_read_end(handles.png, nullptr);
  return true;
}

const char* png_color_type_name(int color_type) {
  switch (color_type) {
    case PNG_COLOR_TYPE_GRAY:
      return "grey";
    case PNG_COLOR_TYPE_GRAY_ALPHA:
      return "grey+alpha";
    case PNG_COLOR_TYPE_PALETTE:
      return "palette";
    case PNG_COLOR_TYPE_RGB:
      return "RGB";
    case PNG_COLOR_TYPE_RGB_ALPHA:
      return "RGBA";
    default:
      return "unknown";
  }
}

// Decodes into `pixels` (bytes, row-major) with the given bytes per pixel after conversion.
void decode_png(const std::vector<uint8_t>& bytes, const std::string& path, PngTarget target,
                std::vector<uint8_t>* pixels, PngLayout* layout) {
  PngSource source;
  source.data = bytes.data();
  source.size = bytes.size();
  PngHandles handles;
  handles.png =
      png_create_read_struct(PNG_LIBPNG_VER_STRING, &source, png_record_error, png_ignore_warning);
  if (handles.png != nullptr) handles.info = png_create_info_struct(handles.png);
  if (handles.png == nullptr || handles.info == nullptr)
    throw Error("'" + path + "': libpng could not start");

  if (!png_start(handles, source, target, layout)) {
    throw Error("'" + path + "': corrupt PNG (" + source.message + ")");
  }
  check_size(layout->width, layout->height, path);
  if (target == PngTarget::kGray16 &&
      (layout->bit_depth != 16 || layout->color_type != PNG_COLOR_TYPE_GRAY)) {
    throw Error("'" + path + "' is a " + std::to_string(layout->bit_depth) + "-bit " +
                png_color_type_name(layout->color_type) +
                " PNG; a depth image must be 16-bit grey");
  }
  const size_t expected_row_bytes =
      static_cast<size_t>(layout->width) * (target == PngTarget::kGray16 ? 2 : 3);
  if (layout->row_bytes != expected_row_bytes) {
    throw Error("'" + path + "': PNG rows decode to " + std::to_string(layout->row_bytes) +
                " bytes, expected " + std::to_string(expected_row_bytes) +
                " (unsupported PNG variant)");
  }
  pixels->resize(expected_row_bytes * layout->height);
  std::vector<png_bytep> rows(layout->height);
  for (uint32_t row = 0; row < layout->height; ++row)
    rows[row] = pixels->data() + row * expected_row_bytes;
  if (!png_finish(handles, rows.data())) {
    throw Error("'" + path + "': corrupt or truncated PNG (" + source.message + ")");
  }
}

#endif  // COVOX_HAVE_PNG

#if COVOX_HAVE_JPEG

// libjpeg's default error handler calls exit(); ours records the message and jumps back.
struct JpegErrorHandler {
  jpeg_error_mgr manager;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
  bool truncated = false;
};

void jpeg_record_error(j_common_ptr info) {
  auto* handler = reinterpret_cast<JpegErrorHandler*>(info->err);
  (*info->err->format_message)(info, handler->message);
  std::longjmp(handler->jump, 1);
}

// Warnings do not stop libjpeg. Most are harmless (extraneous bytes between markers), but
// "premature end of data" means a truncated file whose missing rows libjpeg fills with grey:
// that one must become an error, or a cut-off download reads as a valid image.
void jpeg_note_warning(j_common_ptr info, int level) {
  if (level >= 0) return;  // trace messages
  auto* handler = reinterpret_cast<JpegErrorHandler*>(info->err);
  if (info->err->msg_code == JWRN_JPEG_EOF && !handler->truncated) {
    handler->truncated = true;
    (*info->err->format_message)(info, handler->message);
  }
}

struct JpegDecompressor {
  jpeg_decompress_struct info;
  bool created = false;
  ~JpegDecompressor() {
    if (created) jpeg_destroy_decompress(&info);
  }
};

// Same discipline as the PNG path: everything with a destructor lives in the caller.
bool jpeg_start(JpegDecompressor& decompressor, JpegErrorHandler& handler,
                const std::vector<uint8_t>& bytes) {
  decompressor.info.err = jpeg_std_error(&handler.manager);
  handler.manager.error_exit = jpeg_record_error;
  handler.manager.emit_message = jpeg_note_warning;
  if (setjmp(handler.jump)) return false;
  jpeg_create_decompress(&decompressor.info);
  decompressor.created = true;
  // const_cast: older libjpeg versions declare the buffer non-const; it is only read.
  jpeg_mem_src(&decompressor.info, const_cast<unsigned char*>(bytes.data()),
               static_cast<unsigned long>(bytes.size()));
  jpeg_read_header(&decompressor.info, TRUE);
  decompressor.info.out_color_space = JCS_RGB;  // grey and YCbCr JPEGs alike come out as RGB
  jpeg_start_decompress(&decompressor.info);
  return true;
}

bool jpeg_read_rows(JpegDecompressor& decompressor, JpegErrorHandler& handler, uint8_t* pixels,
                    size_t row_bytes) {
  if (setjmp(handler.jump)) return false;
  while (decompressor.info.output_scanline < decompressor.info.output_height) {
    JSAMPROW row = pixels + decompressor.info.output_scanline * row_bytes;
    jpeg_read_scanlines(&decompressor.info, &row, 1);
  }
  jpeg_finish_decompress(&decompressor.info);
  return true;
}

ColorImage decode_jpeg(const std::vector<uint8_t>& bytes, const std::string& path) {
  JpegDecompressor decompressor;
  JpegErrorHandler handler;
  if (!jpeg_start(decompressor, handler, bytes)) {
    throw Error("'" + path + "': corrupt JPEG (" + handler.message + ")");
  }
  const jpeg_decompress_struct& info = decompressor.info;
  check_size(info.output_width, info.output_height, path);
  if (info.output_components != 3) {
    throw Error("'" + path + "': JPEG decodes to " + std::to_string(info.output_components) +
                " channels, expected 3 (RGB)");
  }
  ColorImage image;
  image.width = static_cast<int>(info.output_width);
  image.height = static_cast<int>(info.output_height);
  image.rgb.resize(static_cast<size_t>(image.width) * image.height * 3);
  if (!jpeg_read_rows(decompressor, handler, image.rgb.data(),
                      static_cast<size_t>(image.width) * 3)) {
    throw Error("'" + path + "': corrupt or truncated JPEG (" + handler.message + ")");
  }
  if (handler.truncated) throw Error("'" + path + "': truncated JPEG (" + handler.message + ")");
  return image;
}

#endif  // COVOX_HAVE_JPEG

[[noreturn, maybe_unused]] void missing_codec(const char* format, const char* library,
                                              const char* package, const std::string& path) {
  throw NotAvailableError("cannot read '" + path + "': this build of covoxslam has no " + format +
                          " reader (" + library + " was not found at configure time; install " +
                          package + " and re-run cmake)");
}

}  // namespace

bool png_reader_available() {
#if COVOX_HAVE_PNG
  return true;
#else
  return false;
#endif
}

bool jpeg_reader_available() {
#if COVOX_HAVE_JPEG
  return true;
#else
  return false;
#endif
}

Gray16Image read_png_gray16(const std::string& path) {
  const std::vector<uint8_t> bytes = read_file_bytes(path);
  if (!starts_with(bytes, kPngSignature, sizeof(kPngSignature))) {
    throw Error("'" + path + "' is not a PNG file (a depth image must be a 16-bit grey PNG)");
  }
#if COVOX_HAVE_PNG
  std::vector<uint8_t> raw;
  PngLayout layout;
  decode_png(bytes, path, PngTarget::kGray16, &raw, &layout);
  Gray16Image image;
  image.width = static_cast<int>(layout.width);
  image.height = static_cast<int>(layout.height);
  image.pixels.resize(static_cast<size_t>(image.width) * image.height);
  std::memcpy(image.pixels.data(), raw.data(), raw.size());
  return image;
#else
  missing_codec("PNG", "libpng", "libpng-dev", path);
#endif
}

ColorImage read_color_image(const std::string& path) {
  const std::vector<uint8_t> bytes = read_file_bytes(path);
  if (starts_with(bytes, kPngSignature, sizeof(kPngSignature))) {
#if COVOX_HAVE_PNG
    ColorImage image;
    PngLayout layout;
    decode_png(bytes, path, PngTarget::kRgb8, &image.rgb, &layout);
    image.width = static_cast<int>(layout.width);
    image.height = static_cast<int>(layout.height);
    return image;
#else
    missing_codec("PNG", "libpng", "libpng-dev", path);
#endif
  }
  if (starts_with(bytes, kJpegSignature, sizeof(kJpegSignature))) {
#if COVOX_HAVE_JPEG
    return decode_jpeg(bytes, path);
#else
    missing_codec("JPEG", "libjpeg", "libjpeg-dev (or libjpeg-turbo8-dev)", path);
#endif
  }
  throw Error("'" + path + "' is neither a PNG nor a JPEG file");
}

ImageSize read_png_size(const std::string& path) {
  // The signature (8 bytes), then the IHDR chunk: length (4), "IHDR" (4), width, height
  // (big-endian uint32 each). PNG requires IHDR to come first.
  constexpr size_t kHeaderBytes = 24;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"),
                                                       &std::fclose);
  if (!file) throw Error("cannot open '" + path + "'");
  std::vector<uint8_t> header(kHeaderBytes);
  const size_t got = std::fread(header.data(), 1, kHeaderBytes, file.get());
  if (got != kHeaderBytes || !starts_with(header, kPngSignature, sizeof(kPngSignature)) ||
      std::memcmp(header.data() + 12, "IHDR", 4) != 0) {
    throw Error("'" + path + "' is not a PNG file (no PNG signature and IHDR header)");
  }
  auto big_endian = [&](size_t at) {
    return (uint32_t(header[at]) << 24) | (uint32_t(header[at + 1]) << 16) |
           (uint32_t(header[at + 2]) << 8) | uint32_t(header[at + 3]);
  };
  const uint32_t width = big_endian(16), height = big_endian(20);
  check_size(width, height, path);
  return ImageSize{static_cast<int>(width), static_cast<int>(height)};
}

}  // namespace io
}  // namespace covox
