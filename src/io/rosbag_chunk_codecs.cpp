#include "covoxslam/io/internal/rosbag_chunk_codecs.h"

#include <memory>
#include <new>

#include "covoxslam/core/error.h"

#if COVOX_HAVE_LZ4
#include <lz4frame.h>
#endif
#if COVOX_HAVE_BZIP2
#include <bzlib.h>
#endif

namespace covox {
namespace io {
namespace rosbag {
namespace {

[[noreturn]] void corrupt(const std::string& what, const std::string& compression,
                          const std::string& problem) {
  throw Error(what + ": corrupt " + compression + " chunk (" + problem + ")");
}

void check_decoded_size(const std::string& what, const std::string& compression, size_t decoded,
                        size_t expected) {
  if (decoded != expected) {
    corrupt(what, compression,
            "decodes to " + std::to_string(decoded) + " bytes, its header says " +
                std::to_string(expected));
  }
}

#if COVOX_HAVE_LZ4
struct Lz4ContextDeleter {
  void operator()(LZ4F_dctx* context) const { LZ4F_freeDecompressionContext(context); }
};

// One LZ4 frame into exactly `output.size()` bytes. LZ4F_decompress consumes input and fills
// output in steps and returns 0 once the frame's end mark (and checksum) has been read.
void decompress_lz4(const uint8_t* stored, size_t stored_size, std::vector<uint8_t>* output,
                    const std::string& what) {
  LZ4F_dctx* raw_context = nullptr;
  const LZ4F_errorCode_t created = LZ4F_createDecompressionContext(&raw_context, LZ4F_VERSION);
  std::unique_ptr<LZ4F_dctx, Lz4ContextDeleter> context(raw_context);
  if (LZ4F_isError(created))
    throw Error(what + ": liblz4 could not start (" + LZ4F_getErrorName(created) + ")");
  size_t read = 0, written = 0;
  for (size_t expects = 1; expects != 0;) {
    if (read == stored_size) corrupt(what, "lz4", "the frame ends early");
    size_t input_size = stored_size - read;
    size_t output_size = output->size() - written;
    expects = LZ4F_decompress(context.get(), output->data() + written, &output_size, stored + read,
                              &input_size, nullptr);
    if (LZ4F_isError(expects)) corrupt(what, "lz4", LZ4F_getErrorName(expects));
    read += input_size;
    written += output_size;
    // No progress with the output full: the frame holds more than the header's size.
    if (expects != 0 && input_size == 0 && output_size == 0) {
      corrupt(
          what, "lz4",
          "decodes to more than the " + std::to_string(output->size()) + " bytes its header says");
    }
  }
  check_decoded_size(what, "lz4", written, output->size());
  if (read != stored_size) {
    corrupt(what, "lz4",
            std::to_string(stored_size - read) + " bytes follow the end of the LZ4 frame");
  }
}
#endif

#if COVOX_HAVE_BZIP2
const char* bzip2_error_name(int code) {
  switch (code) {
    case BZ_DATA_ERROR:
      return "data error";
    case BZ_DATA_ERROR_MAGIC:
      return "not a bzip2 stream";
    case BZ_UNEXPECTED_EOF:
      return "the stream ends early";
    case BZ_OUTBUFF_FULL:
      return "decodes to more bytes than its header says";
    case BZ_MEM_ERROR:
      return "out of memory";
    default:
      return "libbz2 error";
  }
}

void decompress_bz2(const uint8_t* stored, size_t stored_size, std::vector<uint8_t>* output,
                    const std::string& what) {
  // The chunk sizes are uint32 in the bag format, so they fit libbz2's unsigned int sizes.
  unsigned int written = static_cast<unsigned int>(output->size());
  const int status = BZ2_bzBuffToBuffDecompress(
      reinterpret_cast<char*>(output->data()), &written,
      const_cast<char*>(reinterpret_cast<const char*>(stored)),
      static_cast<unsigned int>(stored_size), /*small=*/0, /*verbosity=*/0);
  if (status != BZ_OK) corrupt(what, "bz2", bzip2_error_name(status));
  check_decoded_size(what, "bz2", written, output->size());
}
#endif

}  // namespace

std::string chunk_compression_problem(const std::string& compression) {
  if (compression == "none") return std::string();
  if (compression == "lz4") {
#if COVOX_HAVE_LZ4
    return std::string();
#else
    return "this build has no LZ4 library (liblz4): install liblz4-dev and rebuild";
#endif
  }
  if (compression == "bz2") {
#if COVOX_HAVE_BZIP2
    return std::string();
#else
    return "this build has no bzip2 library (libbz2): install libbz2-dev and rebuild";
#endif
  }
  return "unknown compression (ROS bags use none, lz4 or bz2)";
}

std::vector<uint8_t> decompress_chunk(const std::string& compression, const uint8_t* stored,
                                      size_t stored_size, size_t decompressed_size,
                                      const std::string& what) {
  const std::string problem = chunk_compression_problem(compression);
  if (!problem.empty()) throw Error(what + " is compressed with '" + compression + "': " + problem);
  if (compression == "none") {
    check_decoded_size(what, compression, stored_size, decompressed_size);
    return std::vector<uint8_t>(stored, stored + stored_size);
  }
  std::vector<uint8_t> output;
  try {
    output.resize(decompressed_size);
  } catch (const std::bad_alloc&) {
    throw Error(what + ": cannot hold the " + std::to_string(decompressed_size) +
                " bytes its header says it decompresses to (a corrupt header?)");
  }
#if COVOX_HAVE_LZ4
  if (compression == "lz4") decompress_lz4(stored, stored_size, &output, what);
#endif
#if COVOX_HAVE_BZIP2
  if (compression == "bz2") decompress_bz2(stored, stored_size, &output, what);
#endif
  return output;
}

}  // namespace rosbag
}  // namespace io
}  // namespace covox
