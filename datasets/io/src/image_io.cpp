#include "planeslam/datasets/image_io.hpp"

#include <png.h>
#include <libdeflate.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"
#include "reader_util.hpp"

namespace planeslam::datasets {

InputLimits& GlobalInputLimits() {
  static InputLimits limits;
  return limits;
}

namespace {

// libpng reports errors through longjmp; we keep the message to rethrow as IoError.
struct PngErrorState {
  std::string message;
};

void OnPngError(png_structp png, png_const_charp msg) {
  auto* state = static_cast<PngErrorState*>(png_get_error_ptr(png));
  if (state) state->message = msg ? msg : "unknown libpng error";
  png_longjmp(png, 1);
}

void OnPngWarning(png_structp, png_const_charp) {}

void WriteToStream(png_structp png, png_bytep data, png_size_t length) {
  auto* os = static_cast<std::ostream*>(png_get_io_ptr(png));
  os->write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(length));
}

void FlushStream(png_structp png) { static_cast<std::ostream*>(png_get_io_ptr(png))->flush(); }

}  // namespace

namespace {

// libpng reports errors by longjmp. To keep that well defined, the frames that call setjmp hold no
// C++ objects with destructors and modify nothing of the caller's between setjmp and longjmp except
// through pointers; the caller turns a `false` into an IoError.
struct PngReadHandles {
  png_structp png = nullptr;
  png_infop info = nullptr;
  ~PngReadHandles() {
    if (png) png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
  }
};

struct PngHeader {
  png_uint_32 width = 0;
  png_uint_32 height = 0;
  int bit_depth = 0;
  int color_type = 0;
};

// In-memory source for libpng.
struct MemorySource {
  const unsigned char* data = nullptr;
  std::size_t size = 0;
  std::size_t pos = 0;
};

void ReadFromMemory(png_structp png, png_bytep out, png_size_t length) {
  auto* src = static_cast<MemorySource*>(png_get_io_ptr(png));
  if (length > src->size - src->pos) png_error(png, "unexpected end of file");
  std::memcpy(out, src->data + src->pos, length);
  src->pos += length;
}

bool ReadPngHeader(png_structp png, png_infop info, MemorySource* source, PngHeader* header) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_read_fn(png, source, &ReadFromMemory);
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  header->width = png_get_image_width(png, info);
  header->height = png_get_image_height(png, info);
  header->bit_depth = png_get_bit_depth(png, info);
  header->color_type = png_get_color_type(png, info);
  return true;
}

// Reads all rows (any interlacing) into `rows`, 1 or 2 bytes per pixel in host order.
bool ReadPngRows(png_structp png, png_infop info, int bit_depth, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  if (bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (bit_depth == 16) png_set_swap(png);  // PNG is big-endian; we want host order (x86: little)
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  return true;
}

}  // namespace

Image16 ReadPng16(const std::string& path) {
  return DecodePng16(detail::ReadWholeFile(path, detail::MaxInputFileBytes()), path);
}

namespace {

bool IsPngSignature(const std::string& bytes) {
  return bytes.size() >= 8 &&
         png_sig_cmp(reinterpret_cast<png_const_bytep>(bytes.data()), 0, 8) == 0;
}

bool SizeWithinLimits(std::uint32_t width, std::uint32_t height) {
  const InputLimits& limits = GlobalInputLimits();
  return width > 0 && height > 0 && width <= limits.max_side && height <= limits.max_side &&
         static_cast<std::int64_t>(width) * height <= limits.max_pixels;
}

void CheckPngHeader(std::uint32_t width, std::uint32_t height, int color_type,
                    const std::string& path) {
  if (!SizeWithinLimits(width, height)) {
    throw IoError(path, "image size " + std::to_string(width) + "x" + std::to_string(height) +
                            " is empty or exceeds the input limits");
  }
  if (color_type != PNG_COLOR_TYPE_GRAY) {
    throw IoError(path, "expected a single-channel (grey) PNG, got colour type " +
                            std::to_string(color_type));
  }
}

std::uint32_t BigEndian32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         p[3];
}

/// Per-thread libdeflate decompressor and scratch buffers (frames are decoded on reader threads).
struct InflateScratch {
  libdeflate_decompressor* d = libdeflate_alloc_decompressor();
  std::vector<unsigned char> idat;      // the concatenated IDAT payload
  std::vector<unsigned char> filtered;  // the zlib stream inflated: filter byte + row, per row
  ~InflateScratch() { libdeflate_free_decompressor(d); }
};

/// Sub filter of a 16-bit row (bytes x, `width` pixels), undone into `out` (host order) and, when
/// `keep`, back into x. PNG sums each byte lane separately (modulo 256), so eight pixels are a
/// prefix sum of 16-bit lanes with bytewise adds: three shifted adds, plus the running pixel.
void UnfilterSub16(unsigned char* x, std::size_t width, bool keep, std::uint16_t* out) {
  std::size_t c = 0;
  unsigned char a0 = 0, a1 = 0;
#if defined(__SSE2__)
  __m128i carry = _mm_setzero_si128();
  for (; c + 8 <= width; c += 8) {
    __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(x + 2 * c));
    v = _mm_add_epi8(v, _mm_slli_si128(v, 2));
    v = _mm_add_epi8(v, _mm_slli_si128(v, 4));
    v = _mm_add_epi8(v, _mm_slli_si128(v, 8));
    v = _mm_add_epi8(v, carry);
    if (keep) _mm_storeu_si128(reinterpret_cast<__m128i*>(x + 2 * c), v);
    // Big-endian samples to host order: swap the two bytes of each lane.
    const __m128i swapped = _mm_or_si128(_mm_slli_epi16(v, 8), _mm_srli_epi16(v, 8));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + c), swapped);
    // The last pixel, broadcast to every lane, carries into the next eight.
    const __m128i high = _mm_shufflehi_epi16(v, 0xff);
    carry = _mm_unpackhi_epi64(high, high);
  }
  const int last = _mm_cvtsi128_si32(carry) & 0xffff;
  a0 = static_cast<unsigned char>(last & 0xff);
  a1 = static_cast<unsigned char>(last >> 8);
#endif
  for (; c < width; ++c) {
    a0 = static_cast<unsigned char>(a0 + x[2 * c]);
    a1 = static_cast<unsigned char>(a1 + x[2 * c + 1]);
    out[c] = static_cast<std::uint16_t>((a0 << 8) | a1);
    if (keep) {
      x[2 * c] = a0;
      x[2 * c + 1] = a1;
    }
  }
}

/// Undoes the PNG row filters (PNG spec, section 9) in place, bpp bytes per pixel, and stores
/// the samples (big-endian in the file) in `image`. Sub, the filter depth cameras use, keeps the
/// running pixel in registers (16-bit: UnfilterSub16).
template <int bpp>
bool UnfilterRows(unsigned char* data, std::size_t rows, std::size_t width, Image16* image) {
  const std::size_t row_bytes = width * bpp;
  const unsigned char* prior = nullptr;
  std::uint16_t* out = image->data.data();
  for (std::size_t r = 0; r < rows; ++r, out += width) {
    const unsigned char filter = data[0];
    unsigned char* x = data + 1;
    switch (filter) {
      case 0:
        break;
      case 1: {
        // The unfiltered bytes are written back only when the next row refers to them.
        const bool keep = r + 1 < rows && x[row_bytes] >= 2;
        if constexpr (bpp == 2) {
          UnfilterSub16(x, width, keep, out);
        } else {
          unsigned char a = 0;
          for (std::size_t c = 0; c < width; ++c) {
            a = static_cast<unsigned char>(a + x[c]);
            out[c] = a;
            if (keep) x[c] = a;
          }
        }
        prior = x;
        data += row_bytes + 1;
        continue;
      }
      case 2:
        if (prior) {
          for (std::size_t i = 0; i < row_bytes; ++i) {
            x[i] = static_cast<unsigned char>(x[i] + prior[i]);
          }
        }
        break;
      case 3:
        for (std::size_t i = 0; i < row_bytes; ++i) {
          const unsigned a = i >= bpp ? x[i - bpp] : 0u, b = prior ? prior[i] : 0u;
          x[i] = static_cast<unsigned char>(x[i] + ((a + b) >> 1));
        }
        break;
      case 4:
        for (std::size_t i = 0; i < row_bytes; ++i) {
          const int a = i >= bpp ? x[i - bpp] : 0, b = prior ? prior[i] : 0,
                    c = (i >= bpp && prior) ? prior[i - bpp] : 0;
          const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
          const int pred = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
          x[i] = static_cast<unsigned char>(x[i] + pred);
        }
        break;
      default:
        return false;
    }
    for (std::size_t c = 0; c < width; ++c) {
      out[c] = bpp == 2 ? static_cast<std::uint16_t>((x[2 * c] << 8) | x[2 * c + 1]) : x[c];
    }
    prior = x;
    data += row_bytes + 1;
  }
  return true;
}

/// libdeflate decode of the files depth cameras and planeslam write: grey, 8 or 16 bits, not
/// interlaced, chunks IHDR, IDAT..., IEND only, CRCs and the zlib stream (32 KiB window, Adler-32)
/// exactly consistent. False for anything else, which the caller hands to libpng (its verdict,
/// its message), so accepted files and pixels are libpng's.
bool DecodeGreyWithLibdeflate(const std::string& bytes, Image16* image) {
  thread_local InflateScratch scratch;
  if (scratch.d == nullptr) return false;
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const std::size_t size = bytes.size();
  std::size_t pos = 8;
  std::uint32_t width = 0, height = 0;
  int bit_depth = 0;
  scratch.idat.clear();
  enum { kHeader, kData } stage = kHeader;  // IHDR first; only IDAT, then one IEND, follow
  bool ended = false;
  while (!ended) {
    if (size - pos < 12) return false;
    const std::uint32_t length = BigEndian32(p + pos);
    if (length > 0x7fffffffu || length > size - pos - 12) return false;
    const unsigned char* type = p + pos + 4;
    const unsigned char* body = type + 4;
    if (libdeflate_crc32(0, type, length + 4) != BigEndian32(body + length)) return false;
    if (std::memcmp(type, "IHDR", 4) == 0) {
      if (stage != kHeader || pos != 8 || length != 13) return false;
      width = BigEndian32(body);
      height = BigEndian32(body + 4);
      bit_depth = body[8];
      // colour type grey, compression 0, filter 0, no interlacing
      if ((bit_depth != 8 && bit_depth != 16) || body[9] != 0 || body[10] != 0 || body[11] != 0 ||
          body[12] != 0 || !SizeWithinLimits(width, height)) {
        return false;
      }
      stage = kData;
    } else if (std::memcmp(type, "IDAT", 4) == 0) {
      if (stage != kData) return false;
      scratch.idat.insert(scratch.idat.end(), body, body + length);
    } else if (std::memcmp(type, "IEND", 4) == 0) {
      if (stage != kData || scratch.idat.empty() || length != 0) return false;
      ended = true;
    } else {
      return false;
    }
    pos += std::size_t{length} + 12;
  }
  const std::size_t bpp = bit_depth / 8;
  const std::size_t row_bytes = std::size_t{width} * bpp;
  const std::size_t inflated = std::size_t{height} * (row_bytes + 1);
  // zlib header: deflate with a 32 KiB window (CINFO 7). Smaller windows make zlib refuse
  // distances libdeflate would accept, so those files go to libpng.
  if (scratch.idat.size() < 2 || (scratch.idat[0] & 0xf0) != 0x70) return false;
  scratch.filtered.resize(inflated);
  std::size_t consumed = 0;
  if (libdeflate_zlib_decompress_ex(scratch.d, scratch.idat.data(), scratch.idat.size(),
                                    scratch.filtered.data(), inflated, &consumed,
                                    nullptr) != LIBDEFLATE_SUCCESS ||
      consumed != scratch.idat.size()) {
    return false;
  }
  *image = Image16(static_cast<int>(width), static_cast<int>(height));
  const bool ok = bpp == 2 ? UnfilterRows<2>(scratch.filtered.data(), height, width, image)
                           : UnfilterRows<1>(scratch.filtered.data(), height, width, image);
  if (!ok) return false;
  return true;
}

}  // namespace

Image16 DecodePng16(const std::string& bytes, const std::string& path) {
  if (!IsPngSignature(bytes)) throw IoError(path, "not a PNG file");
  Image16 image;
  if (DecodeGreyWithLibdeflate(bytes, &image)) return image;
  return DecodePng16WithLibpng(bytes, path);
}

Image16 DecodePng16WithLibpng(const std::string& bytes, const std::string& path) {
  if (!IsPngSignature(bytes)) throw IoError(path, "not a PNG file");
  MemorySource source;
  source.data = reinterpret_cast<const unsigned char*>(bytes.data());
  source.size = bytes.size();
  source.pos = 8;
  PngErrorState state;
  PngReadHandles handles;
  handles.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, &OnPngError, &OnPngWarning);
  if (!handles.png) throw IoError(path, "cannot initialise libpng");
  handles.info = png_create_info_struct(handles.png);
  if (!handles.info) throw IoError(path, "cannot initialise libpng");
  // Let libpng accept any header size the format allows (its default stops at 10^6 px a side with
  // a cryptic message); our own limits below refuse it by name before anything is allocated.
  png_set_user_limits(handles.png, 0x7fffffffU, 0x7fffffffU);
  PngHeader h;
  if (!ReadPngHeader(handles.png, handles.info, &source, &h)) {
    throw IoError(path, "corrupt or truncated PNG (" + state.message + ")");
  }
  CheckPngHeader(h.width, h.height, h.color_type, path);
  Image16 image(static_cast<int>(h.width), static_cast<int>(h.height));
  std::vector<png_byte> bytes8;  // 8-bit (or less) images are widened after reading
  std::vector<png_bytep> rows(h.height);
  for (png_uint_32 r = 0; r < h.height; ++r) {
    if (h.bit_depth == 16) {
      rows[r] =
          reinterpret_cast<png_bytep>(image.data.data() + static_cast<std::size_t>(r) * h.width);
    }
  }
  if (h.bit_depth != 16) {
    bytes8.resize(static_cast<std::size_t>(h.width) * h.height);
    for (png_uint_32 r = 0; r < h.height; ++r) {
      rows[r] = bytes8.data() + static_cast<std::size_t>(r) * h.width;
    }
  }
  if (!ReadPngRows(handles.png, handles.info, h.bit_depth, rows.data())) {
    throw IoError(path, "corrupt or truncated PNG (" + state.message + ")");
  }
  if (h.bit_depth != 16) std::copy(bytes8.begin(), bytes8.end(), image.data.begin());
  return image;
}

namespace {

void WritePng(const std::string& path, int width, int height, int color_type, int bit_depth,
              const std::uint8_t* data, std::size_t row_bytes) {
  PLANESLAM_CHECK(width > 0 && height > 0, "empty image for " << path);
  AtomicOutputFile out(path, /*binary=*/true);
  PngErrorState state;
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, &OnPngError, &OnPngWarning);
  if (!png) throw IoError(path, "cannot initialise libpng");
  png_infop info = png_create_info_struct(png);
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw IoError(path, "PNG write failed (" + state.message + ")");
  }
  png_set_write_fn(png, &out.stream(), &WriteToStream, &FlushStream);
  png_set_IHDR(png, info, width, height, bit_depth, color_type, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  // Level 1: depth/label images compress nearly as well, several times faster than the default.
  png_set_compression_level(png, 1);
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);
  for (int r = 0; r < height; ++r) {
    png_write_row(png, const_cast<png_bytep>(data + static_cast<std::size_t>(r) * row_bytes));
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  out.Commit();
}

}  // namespace

void WritePng16(const std::string& path, const Image16& image) {
  PLANESLAM_CHECK(image.data.size() == static_cast<std::size_t>(image.width) * image.height,
                  "image buffer size mismatch");
  WritePng(path, image.width, image.height, PNG_COLOR_TYPE_GRAY, 16,
           reinterpret_cast<const std::uint8_t*>(image.data.data()),
           static_cast<std::size_t>(image.width) * 2);
}

void WritePngRgb(const std::string& path, const ImageRgb8& image) {
  PLANESLAM_CHECK(image.data.size() == static_cast<std::size_t>(image.width) * image.height * 3,
                  "image buffer size mismatch");
  WritePng(path, image.width, image.height, PNG_COLOR_TYPE_RGB, 8, image.data.data(),
           static_cast<std::size_t>(image.width) * 3);
}

std::array<std::uint8_t, 3> LabelColour(int id) {
  if (id <= 0) return {110, 110, 110};  // no plane: neutral grey
  // Hue steps by the golden ratio conjugate: consecutive ids get well separated hues; value
  // alternates so that ids with nearby hues (id and id + 13 or so) still differ.
  const double h = std::fmod(0.1 + 0.618033988749895 * id, 1.0) * 6.0;
  const double v = (id % 2 == 0) ? 0.95 : 0.75;
  const double s = 0.75;
  const int sector = static_cast<int>(std::floor(h)) % 6;
  const double f = h - std::floor(h);
  const double p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  double r = 0, g = 0, b = 0;
  switch (sector) {
    case 0:
      r = v, g = t, b = p;
      break;
    case 1:
      r = q, g = v, b = p;
      break;
    case 2:
      r = p, g = v, b = t;
      break;
    case 3:
      r = p, g = q, b = v;
      break;
    case 4:
      r = t, g = p, b = v;
      break;
    default:
      r = v, g = p, b = q;
      break;
  }
  auto byte = [](double x) {
    return static_cast<std::uint8_t>(std::lround(std::clamp(x, 0.0, 1.0) * 255.0));
  };
  return {byte(r), byte(g), byte(b)};
}

}  // namespace planeslam::datasets
