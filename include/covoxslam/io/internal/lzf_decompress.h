#pragma once
// LZF decompression, as used by PCD `binary_compressed`. Written from the format description:
// a stream of chunks, each starting with a control byte C:
//   C < 32:  a literal run, the next C + 1 bytes are copied to the output;
//   C >= 32: a back reference of length L = C >> 5 (when L == 7 the next byte is added to L),
//            offset O = ((C & 31) << 8) + next byte; L + 2 bytes are copied from O + 1 bytes
//            before the current output end (byte by byte: the ranges may overlap).
#include <cstddef>
#include <cstdint>
#include <string>

namespace covox {
namespace io {

// Decompresses `input` into exactly `output_size` bytes at `output`. Throws covox::Error (with
// `context`, e.g. the file path, in the message) when the stream is malformed, reads past its
// end, references before the start of the output, or does not produce exactly output_size bytes.
void lzf_decompress(const uint8_t* input, size_t input_size, uint8_t* output, size_t output_size,
                    const std::string& context);

}  // namespace io
}  // namespace covox
