#pragma once
// Decompression of ROS bag chunks. A chunk record holds its message and connection records
// either as they are (compression "none") or compressed as one stream: "bz2" (a bzip2 stream,
// decoded by libbz2) or "lz4" (one LZ4 frame, magic 0x184D2204, which is what rosbag's roslz4
// writes; decoded by liblz4's frame API). The chunk header's `size` is the size of the records
// once decompressed, so a stream that decodes to any other size is corrupt.
//
// Both libraries are optional at build time (COVOX_HAVE_LZ4, COVOX_HAVE_BZIP2): a build without
// one refuses that compression with a message naming the library and its Debian package.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace covox {
namespace io {
namespace rosbag {

// Empty when this build reads chunks compressed with `compression` ("none", "lz4", "bz2");
// otherwise why not: the missing library and how to get it, or that the compression is unknown.
std::string chunk_compression_problem(const std::string& compression);

// The `decompressed_size` bytes of a chunk whose stored (compressed) bytes are `stored`. Throws
// covox::Error naming `what` for corrupt data, for a stream that decodes to another size than
// `decompressed_size`, and for a compression chunk_compression_problem() refuses.
std::vector<uint8_t> decompress_chunk(const std::string& compression, const uint8_t* stored,
                                      size_t stored_size, size_t decompressed_size,
                                      const std::string& what);

}  // namespace rosbag
}  // namespace io
}  // namespace covox
