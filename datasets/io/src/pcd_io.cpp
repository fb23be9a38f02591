#include "planeslam/datasets/pcd_io.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"
#include "reader_util.hpp"

namespace planeslam::datasets {

namespace {

constexpr std::size_t kMaxFields = 1024;
// PCL pads binary_compressed files with zeros after the payload (to a page boundary); more than a
// page of trailing bytes means the header or the size words lie.
constexpr std::size_t kMaxCompressedPadding = 4096;

std::string ToStr(std::int64_t v) { return std::to_string(v); }

// Reads one element of a field as double (PCD binary data is little-endian on every platform PCL
// writes on; we assume a little-endian host as PCL does).
inline double ReadElement(const char* p, int size, char type) {
  if (type == 'F' && size == 4) {  // the common case first
    float f;
    std::memcpy(&f, p, 4);
    return f;
  }
  switch (type) {
    case 'F':
      if (size == 4) {
        float f;
        std::memcpy(&f, p, 4);
        return f;
      } else {
        double d;
        std::memcpy(&d, p, 8);
        return d;
      }
    case 'I':
      switch (size) {
        case 1: {
          std::int8_t v;
          std::memcpy(&v, p, 1);
          return v;
        }
        case 2: {
          std::int16_t v;
          std::memcpy(&v, p, 2);
          return v;
        }
        case 4: {
          std::int32_t v;
          std::memcpy(&v, p, 4);
          return v;
        }
        default: {
          std::int64_t v;
          std::memcpy(&v, p, 8);
          return static_cast<double>(v);
        }
      }
    default:
      switch (size) {
        case 1: {
          std::uint8_t v;
          std::memcpy(&v, p, 1);
          return v;
        }
        case 2: {
          std::uint16_t v;
          std::memcpy(&v, p, 2);
          return v;
        }
        case 4: {
          std::uint32_t v;
          std::memcpy(&v, p, 4);
          return v;
        }
        default: {
          std::uint64_t v;
          std::memcpy(&v, p, 8);
          return static_cast<double>(v);
        }
      }
  }
}

// ascii values may be nan/inf (PCL prints "nan" for invalid points).
bool ParseAsciiValue(std::string_view token, double* value) {
  if (token.empty() || token.size() > 64) return false;
  char buf[65];
  token.copy(buf, token.size());
  buf[token.size()] = '\0';
  char* end = nullptr;
  *value = std::strtod(buf, &end);
  return end == buf + token.size();
}

struct XyzLayout {
  int field[3];               // indices of x, y, z
  std::size_t offset[3];      // byte offset within a point (AoS)
  std::size_t soa_offset[3];  // byte offset of the field's block per point count (SoA)
  std::size_t element[3];     // element index among all elements of a point (ascii)
};

XyzLayout FindXyz(const PcdHeader& h, const std::string& name) {
  XyzLayout layout{};
  const char* names[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k) {
    layout.field[k] = h.FieldIndex(names[k]);
    if (layout.field[k] < 0) {
      throw IoError(name,
                    std::string("PCD has no field '") + names[k] + "' (FIELDS must include x y z)");
    }
    std::size_t offset = 0, element = 0;
    for (int f = 0; f < layout.field[k]; ++f) {
      offset += static_cast<std::size_t>(h.fields[f].size) * h.fields[f].count;
      element += h.fields[f].count;
    }
    layout.offset[k] = offset;
    layout.soa_offset[k] = offset;  // the block of field f starts at points * offset
    layout.element[k] = element;
  }
  return layout;
}

void StorePoint(OrganizedCloud* cloud, std::size_t i, double x, double y, double z, double scale) {
  if (std::isfinite(x) && std::isfinite(y) && std::isfinite(z)) {
    cloud->points[i] = Eigen::Vector3f(static_cast<float>(x * scale), static_cast<float>(y * scale),
                                       static_cast<float>(z * scale));
  }  // else stays NaN (the constructor fills NaN)
}

}  // namespace

int PcdHeader::FieldIndex(const std::string& field_name) const {
  for (std::size_t i = 0; i < fields.size(); ++i) {
    if (fields[i].name == field_name) return static_cast<int>(i);
  }
  return -1;
}

PcdHeader ParsePcdHeader(const std::string& bytes, const std::string& name) {
  PcdHeader h;
  std::size_t pos = 0;
  long line_no = 0;
  bool have_fields = false, have_size = false, have_type = false, have_count = false;
  bool have_width = false, have_height = false, have_points = false;
  std::vector<std::string_view> sizes, types, counts;
  while (true) {
    if (pos >= bytes.size()) throw IoError(name, "not a PCD file (no DATA line in the header)");
    std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    std::string_view line(bytes.data() + pos, end - pos);
    pos = std::min(end + 1, bytes.size());
    ++line_no;
    if (line_no > 1000)
      throw IoError(name, "not a PCD file (no DATA line in the first 1000 lines)");
    line = detail::Trim(line);
    if (line.empty() || line.front() == '#') continue;
    const auto tok = detail::SplitWhitespace(line);
    const std::string_view key = tok[0];
    const std::size_t n = tok.size() - 1;
    auto need = [&](std::size_t count) {
      if (n != count) {
        throw IoError(name, line_no,
                      std::string(key) + " expects " + std::to_string(count) + " value(s), got " +
                          std::to_string(n));
      }
    };
    auto integer = [&](std::string_view t) {
      std::int64_t v = 0;
      if (!detail::ParseInt64(t, &v) || t.size() > 18) {
        throw IoError(
            name, line_no,
            std::string(key) + ": expected a non-negative integer, got '" + std::string(t) + "'");
      }
      return v;
    };
    if (key == "VERSION") {
      continue;
    } else if (key == "FIELDS") {
      if (n == 0 || n > kMaxFields)
        throw IoError(name, line_no, "FIELDS: expected 1 to 1024 names");
      h.fields.resize(n);
      for (std::size_t i = 0; i < n; ++i) h.fields[i].name = std::string(tok[i + 1]);
      have_fields = true;
    } else if (key == "SIZE") {
      sizes.assign(tok.begin() + 1, tok.end());
      have_size = true;
    } else if (key == "TYPE") {
      types.assign(tok.begin() + 1, tok.end());
      have_type = true;
    } else if (key == "COUNT") {
      counts.assign(tok.begin() + 1, tok.end());
      have_count = true;
    } else if (key == "WIDTH") {
      need(1);
      h.width = integer(tok[1]);
      have_width = true;
    } else if (key == "HEIGHT") {
      need(1);
      h.height = integer(tok[1]);
      have_height = true;
    } else if (key == "POINTS") {
      need(1);
      h.points = integer(tok[1]);
      have_points = true;
    } else if (key == "VIEWPOINT") {
      need(7);
    } else if (key == "DATA") {
      need(1);
      h.data = std::string(tok[1]);
      if (h.data != "ascii" && h.data != "binary" && h.data != "binary_compressed") {
        throw IoError(
            name, line_no,
            "unknown DATA kind '" + h.data + "' (expected ascii, binary or binary_compressed)");
      }
      h.data_offset = pos;
      break;
    } else {
      throw IoError(name, line_no, "unknown header keyword '" + std::string(key) + "'");
    }
  }
  if (!have_fields) throw IoError(name, "PCD header has no FIELDS line");
  if (!have_size || !have_type) throw IoError(name, "PCD header lacks SIZE or TYPE");
  if (!have_width || !have_height) throw IoError(name, "PCD header lacks WIDTH or HEIGHT");
  const std::size_t nf = h.fields.size();
  if (sizes.size() != nf || types.size() != nf || (have_count && counts.size() != nf)) {
    throw IoError(name, "SIZE, TYPE and COUNT must have one entry per field (" +
                            std::to_string(nf) + " fields)");
  }
  for (std::size_t i = 0; i < nf; ++i) {
    PcdField& f = h.fields[i];
    std::int64_t size = 0, count = 1;
    if (!detail::ParseInt64(sizes[i], &size) ||
        (size != 1 && size != 2 && size != 4 && size != 8)) {
      throw IoError(name, "field '" + f.name + "': SIZE must be 1, 2, 4 or 8, got '" +
                              std::string(sizes[i]) + "'");
    }
    if (types[i].size() != 1 || (types[i][0] != 'F' && types[i][0] != 'I' && types[i][0] != 'U')) {
      throw IoError(name, "field '" + f.name + "': TYPE must be F, I or U, got '" +
                              std::string(types[i]) + "'");
    }
    if (types[i][0] == 'F' && size != 4 && size != 8) {
      throw IoError(name, "field '" + f.name + "': a float field must have SIZE 4 or 8");
    }
    if (have_count && (!detail::ParseInt64(counts[i], &count) || count < 1 || count > 1 << 20)) {
      throw IoError(name, "field '" + f.name + "': COUNT must be an integer in [1, 2^20], got '" +
                              std::string(counts[i]) + "'");
    }
    f.size = static_cast<int>(size);
    f.type = types[i][0];
    f.count = static_cast<int>(count);
    h.point_bytes += static_cast<std::size_t>(size) * static_cast<std::size_t>(count);
  }
  // Sizes are checked against the limits before any multiplication can overflow.
  const InputLimits& limits = GlobalInputLimits();
  if (h.width < 1 || h.height < 1) {
    throw IoError(name, "WIDTH and HEIGHT must be at least 1 (got " + ToStr(h.width) + "x" +
                            ToStr(h.height) + ")");
  }
  const bool organized = h.height > 1;
  const bool fits = organized ? (h.width <= limits.max_side && h.height <= limits.max_side &&
                                 h.width * h.height <= limits.max_pixels)
                              : h.width <= limits.max_points;
  if (!fits) {
    throw IoError(name, "cloud of " + ToStr(h.width) + "x" + ToStr(h.height) +
                            " points exceeds the input limits");
  }
  if (!have_points) h.points = h.width * h.height;
  if (h.points != h.width * h.height) {
    throw IoError(name, "header says POINTS " + ToStr(h.points) + " but WIDTH x HEIGHT is " +
                            ToStr(h.width) + "x" + ToStr(h.height) + " = " +
                            ToStr(h.width * h.height));
  }
  if (h.point_bytes > (1u << 24)) throw IoError(name, "point record too large");
  return h;
}

std::string LzfDecompress(const char* in, std::size_t in_size, std::size_t expected_size,
                          const std::string& name) {
  std::string out(expected_size, '\0');
  const auto* ip = reinterpret_cast<const unsigned char*>(in);
  const unsigned char* const ip_end = ip + in_size;
  auto* const out_begin = reinterpret_cast<unsigned char*>(out.data());
  unsigned char* op = out_begin;
  unsigned char* const op_end = out_begin + expected_size;
  auto corrupt = [&](const std::string& why) {
    return IoError(name, "corrupt LZF data at compressed byte " +
                             std::to_string(ip - reinterpret_cast<const unsigned char*>(in)) +
                             " (" + why + ")");
  };
  while (ip < ip_end) {
    unsigned int ctrl = *ip++;
    if (ctrl < 32) {  // literal run of ctrl + 1 bytes
      const std::size_t len = ctrl + 1;
      if (static_cast<std::size_t>(ip_end - ip) < len) throw corrupt("literal run past the end");
      if (static_cast<std::size_t>(op_end - op) < len) {
        throw corrupt("decompresses to more than " + std::to_string(expected_size) + " bytes");
      }
      std::memcpy(op, ip, len);
      op += len;
      ip += len;
    } else {  // back reference: length (ctrl >> 5) + 2, distance ((ctrl & 31) << 8 | next) + 1
      std::size_t len = ctrl >> 5;
      if (ip >= ip_end) throw corrupt("back reference past the end");
      if (len == 7) {
        len += *ip++;
        if (ip >= ip_end) throw corrupt("back reference past the end");
      }
      const std::size_t distance = ((static_cast<std::size_t>(ctrl & 0x1f) << 8) | *ip++) + 1;
      len += 2;
      if (distance > static_cast<std::size_t>(op - out_begin)) {
        throw corrupt("back reference before the start");
      }
      if (static_cast<std::size_t>(op_end - op) < len) {
        throw corrupt("decompresses to more than " + std::to_string(expected_size) + " bytes");
      }
      const unsigned char* ref = op - distance;
      if (distance >= len) {
        std::memcpy(op, ref, len);
        op += len;
      } else {
        // Overlapping (run-length style) reference: must go byte by byte.
        for (std::size_t k = 0; k < len; ++k) *op++ = *ref++;
      }
    }
  }
  if (op != op_end) {
    throw IoError(name, "LZF data decompresses to " + std::to_string(op - out_begin) +
                            " bytes, the header announces " + std::to_string(expected_size));
  }
  return out;
}

OrganizedCloud ParsePcd(const std::string& bytes, const std::string& name, double unit_scale,
                        SensorModel model) {
  const PcdHeader h = ParsePcdHeader(bytes, name);
  const XyzLayout xyz = FindXyz(h, name);
  const std::size_t n = static_cast<std::size_t>(h.points);
  const std::size_t available = bytes.size() - h.data_offset;
  const char* data = bytes.data() + h.data_offset;
  const std::size_t expected = n * h.point_bytes;

  // Validate the data size before allocating the cloud.
  std::string decompressed;
  if (h.data == "binary") {
    if (available < expected) {
      throw IoError(name, "truncated: header announces " + std::to_string(n) + " points (" +
                              std::to_string(expected) + " bytes of data), found " +
                              std::to_string(available) + " bytes");
    }
    if (available > expected) {
      throw IoError(name, std::to_string(available - expected) + " bytes of data beyond the " +
                              std::to_string(n) + " points the header announces");
    }
  } else if (h.data == "binary_compressed") {
    if (available < 8)
      throw IoError(name, "truncated: binary_compressed data lacks its size words");
    std::uint32_t compressed = 0, uncompressed = 0;
    std::memcpy(&compressed, data, 4);
    std::memcpy(&uncompressed, data + 4, 4);
    if (uncompressed != expected) {
      throw IoError(name, "compressed block says " + std::to_string(uncompressed) +
                              " bytes uncompressed, the header needs " + std::to_string(expected) +
                              " (" + std::to_string(n) + " points of " +
                              std::to_string(h.point_bytes) + " bytes)");
    }
    if (compressed > available - 8) {
      throw IoError(name, "truncated: compressed block of " + std::to_string(compressed) +
                              " bytes, only " + std::to_string(available - 8) + " present");
    }
    // LZF expands at most 88x (a 3-byte reference yields up to 264 bytes): a larger claim cannot be
    // true, and refusing it keeps the allocation tied to the bytes actually present.
    if (uncompressed > 88ull * compressed + 64) {
      throw IoError(name, "compressed block of " + std::to_string(compressed) +
                              " bytes cannot expand to the " + std::to_string(uncompressed) +
                              " bytes the header needs");
    }
    if (available - 8 - compressed > kMaxCompressedPadding) {
      throw IoError(name,
                    std::to_string(available - 8 - compressed) +
                        " bytes after the compressed block (size words disagree with the file)");
    }
    decompressed = LzfDecompress(data + 8, compressed, expected, name);
  } else {
    // ascii: every point needs at least one character and one separator per value.
    std::size_t elements = 0;
    for (const auto& f : h.fields) elements += f.count;
    if (available + 1 < n * elements * 2) {
      throw IoError(name, "truncated: " + std::to_string(available) +
                              " bytes of ascii data cannot hold the " + std::to_string(n) +
                              " points the header announces");
    }
  }

  OrganizedCloud cloud(static_cast<int>(h.width), static_cast<int>(h.height), model);
  const double s = unit_scale;
  if (h.data == "binary") {
    for (std::size_t i = 0; i < n; ++i) {
      const char* p = data + i * h.point_bytes;
      double v[3];
      for (int k = 0; k < 3; ++k) {
        const PcdField& f = h.fields[xyz.field[k]];
        v[k] = ReadElement(p + xyz.offset[k], f.size, f.type);
      }
      StorePoint(&cloud, i, v[0], v[1], v[2], s);
    }
  } else if (h.data == "binary_compressed") {
    // Structure of arrays: field f occupies bytes [n * offset_f, n * (offset_f + bytes_f)).
    const char* base = decompressed.data();
    for (std::size_t i = 0; i < n; ++i) {
      double v[3];
      for (int k = 0; k < 3; ++k) {
        const PcdField& f = h.fields[xyz.field[k]];
        const std::size_t field_bytes = static_cast<std::size_t>(f.size) * f.count;
        v[k] = ReadElement(base + n * xyz.soa_offset[k] + i * field_bytes, f.size, f.type);
      }
      StorePoint(&cloud, i, v[0], v[1], v[2], s);
    }
  } else {  // ascii: one point per non-empty line
    std::size_t elements = 0;
    for (const auto& f : h.fields) elements += f.count;
    std::size_t i = 0;
    std::size_t pos = h.data_offset;
    long line_no = 0;
    std::vector<std::string_view> tok;
    while (pos < bytes.size()) {
      std::size_t end = bytes.find('\n', pos);
      if (end == std::string::npos) end = bytes.size();
      const std::string_view line = detail::Trim(std::string_view(bytes.data() + pos, end - pos));
      pos = end + 1;
      ++line_no;
      if (line.empty()) continue;
      if (i == n) {
        throw IoError(
            name, "more ascii data than the " + std::to_string(n) + " points the header announces");
      }
      tok = detail::SplitWhitespace(line);
      if (tok.size() != elements) {
        throw IoError(name, "ascii point " + std::to_string(i) + " has " +
                                std::to_string(tok.size()) + " values, the header announces " +
                                std::to_string(elements));
      }
      double v[3];
      for (int k = 0; k < 3; ++k) {
        if (!ParseAsciiValue(tok[xyz.element[k]], &v[k])) {
          throw IoError(name, "ascii point " + std::to_string(i) + ": not a number '" +
                                  std::string(tok[xyz.element[k]]) + "'");
        }
      }
      StorePoint(&cloud, i, v[0], v[1], v[2], s);
      ++i;
    }
    if (i != n) {
      throw IoError(name, "truncated: header announces " + std::to_string(n) +
                              " points, ascii data has " + std::to_string(i));
    }
  }
  return cloud;
}

OrganizedCloud ReadPcd(const std::string& path, double unit_scale, SensorModel model) {
  return ParsePcd(detail::ReadWholeFile(path, detail::MaxInputFileBytes()), path, unit_scale,
                  model);
}

void WritePcd(const std::string& path, const OrganizedCloud& cloud,
              const std::vector<std::uint32_t>* rgb) {
  PLANESLAM_CHECK(cloud.points.size() == static_cast<std::size_t>(cloud.width) * cloud.height,
                  "cloud size mismatch");
  PLANESLAM_CHECK(!rgb || rgb->size() == cloud.points.size(), "rgb size mismatch");
  std::ostringstream header;
  header << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n";
  header << (rgb ? "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
                 : "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n");
  header << "WIDTH " << cloud.width << "\nHEIGHT " << cloud.height
         << "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << cloud.points.size() << "\nDATA binary\n";
  const std::size_t stride = rgb ? 16 : 12;
  std::string bytes = header.str();
  const std::size_t start = bytes.size();
  bytes.resize(start + stride * cloud.points.size());
  char* out = bytes.data() + start;
  for (std::size_t i = 0; i < cloud.points.size(); ++i, out += stride) {
    std::memcpy(out, cloud.points[i].data(), 12);
    // PCL packs rgb as the bits of a float: 0x00RRGGBB.
    if (rgb) std::memcpy(out + 12, &(*rgb)[i], 4);
  }
  WriteFileAtomic(path, bytes);
}

}  // namespace planeslam::datasets
