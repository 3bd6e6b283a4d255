#include "covoxslam/io/internal/lzf_decompress.h"

#include <cstring>

#include "covoxslam/core/error.h"

namespace covox {
namespace io {
namespace {

constexpr unsigned kLiteralLimit = 32;        // control bytes below this start a literal run
constexpr unsigned kLongReferenceLength = 7;  // the length field value that says "one more byte"
constexpr size_t kMinimumReferenceLength = 2;

[[noreturn]] void fail(const std::string& context, const std::string& what, size_t input_position) {
  throw Error(context + ": corrupt LZF data (" + what + " at compressed byte " +
              std::to_string(input_position) + ")");
}

}  // namespace

void lzf_decompress(const uint8_t* input, size_t input_size, uint8_t* output, size_t output_size,
                    const std::string& context) {
  size_t in = 0;
  size_t out = 0;
  while (in < input_size) {
    const size_t chunk_start = in;
    const unsigned control = input[in++];
    if (control < kLiteralLimit) {
      const size_t length = control + 1;
      if (in + length > input_size)
        fail(context, "literal run past the end of the input", chunk_start);
      if (out + length > output_size)
        fail(context, "literal run past the expected output size", chunk_start);
      std::memcpy(output + out, input + in, length);
      in += length;
      out += length;
      continue;
    }
    size_t length = control >> 5;
    if (length == kLongReferenceLength) {
      if (in >= input_size)
        fail(context, "back reference length past the end of the input", chunk_start);
      length += input[in++];
    }
    if (in >= input_size)
      fail(context, "back reference offset past the end of the input", chunk_start);
    const size_t distance = ((static_cast<size_t>(control & 0x1f) << 8) | input[in++]) + 1;
    length += kMinimumReferenceLength;
    if (distance > out) fail(context, "back reference before the start of the output", chunk_start);
    if (out + length > output_size)
      fail(context, "back reference past the expected output size", chunk_start);
    // Byte by byte on purpose: with distance < length the copy repeats bytes it just wrote
    // (that is how LZF encodes runs), which memcpy/memmove would not do.
    const uint8_t* source = output + out - distance;
    for (size_t i = 0; i < length; ++i) output[out + i] = source[i];
    out += length;
  }
  if (out != output_size) {
    throw Error(context + ": LZF data decompressed to " + std::to_string(out) +
                " bytes, expected " + std::to_string(output_size) + " (truncated or corrupt)");
  }
}

}  // namespace io
}  // namespace covox
