#pragma once
/// Point Cloud Library's PCD format, read and written without PCL.
///
/// Reads DATA ascii, binary and binary_compressed (LZF; PCL stores the compressed payload field by
/// field: all x, then all y, ...). Fields x y z are required (any SIZE/TYPE/COUNT; the first
/// element is used); every other field is skipped. The header is checked against the data before
/// anything is allocated: POINTS != WIDTH*HEIGHT, data shorter or longer than announced, sizes
/// that disagree, an unknown DATA kind, missing fields or a size beyond the input limits all throw
/// IoError naming the file and the problem.
#include <cstdint>
#include <string>
#include <vector>

#include "planeslam/datasets/organized_cloud.hpp"

namespace planeslam::datasets {

/// One FIELDS entry of a PCD header.
struct PcdField {
  std::string name;
  int size = 4;     ///< bytes per element (1, 2, 4 or 8)
  char type = 'F';  ///< 'F' float, 'I' signed, 'U' unsigned
  int count = 1;    ///< elements
};

/// A parsed PCD header.
struct PcdHeader {
  std::vector<PcdField> fields;
  std::int64_t width = 0;
  std::int64_t height = 0;
  std::int64_t points = 0;
  std::string data;             ///< "ascii", "binary" or "binary_compressed"
  std::size_t data_offset = 0;  ///< byte offset of the data after the DATA line
  std::size_t point_bytes = 0;  ///< sum of size * count

  /// Index of the field called `name`, or -1.
  int FieldIndex(const std::string& name) const;
};

/// Parses the header of a PCD held in `bytes`; `name` is used in messages.
PcdHeader ParsePcdHeader(const std::string& bytes, const std::string& name);

/// Parses a whole PCD held in memory. Coordinates are multiplied by `unit_scale` (e.g. 0.01 for
/// centimetres). A point with any non-finite coordinate becomes NaN in all three. The cloud's
/// model is `model`; HEIGHT 1 (unorganized) gives a width x 1 cloud.
OrganizedCloud ParsePcd(const std::string& bytes, const std::string& name, double unit_scale = 1.0,
                        SensorModel model = SensorModel::kPinhole);

/// Reads a PCD file (see ParsePcd).
OrganizedCloud ReadPcd(const std::string& path, double unit_scale = 1.0,
                       SensorModel model = SensorModel::kPinhole);

/// LZF decompression (liblzf format, as PCL uses). Throws IoError(name, reason) when the stream is
/// corrupt or does not decompress to exactly `expected_size` bytes.
std::string LzfDecompress(const char* in, std::size_t in_size, std::size_t expected_size,
                          const std::string& name);

/// Writes an organized cloud as binary PCD (x y z float32, plus a packed `rgb` float field when
/// `rgb` is given: one 0xRRGGBB value per point), atomically. NaN points stay NaN so the grid is
/// kept; PCL's io::loadPCDFile reads it back.
void WritePcd(const std::string& path, const OrganizedCloud& cloud,
              const std::vector<std::uint32_t>* rgb = nullptr);

}  // namespace planeslam::datasets
