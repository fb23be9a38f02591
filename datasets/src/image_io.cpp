#include "planeslam/datasets/image_io.hpp"

#include <png.h>

#include <csetjmp>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>

#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"

namespace planeslam::datasets {

InputLimits& GlobalInputLimits() {
  static InputLimits limits;
  return limits;
}

namespace {

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f) std::fclose(f);
  }
};

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

Image16 ReadPng16(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) throw IoError(path, "no such file");
  std::unique_ptr<std::FILE, FileCloser> file(std::fopen(path.c_str(), "rb"));
  if (!file) throw IoError(path, "cannot open file");
  unsigned char signature[8] = {};
  if (std::fread(signature, 1, 8, file.get()) != 8 || png_sig_cmp(signature, 0, 8) != 0) {
    throw IoError(path, "not a PNG file");
  }
  PngErrorState state;
  png_structp png =
      png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, &OnPngError, &OnPngWarning);
  if (!png) throw IoError(path, "cannot initialise libpng");
  png_infop info = png_create_info_struct(png);
  Image16 image;
  std::vector<png_byte> row;
  // Everything libpng touches after setjmp must not need destructors on the longjmp path except
  // what we clean up explicitly below; `image` and `row` are declared before setjmp so
  // their destructors run normally when we throw.
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw IoError(path, "corrupt or truncated PNG (" + state.message + ")");
  }
  png_init_io(png, file.get());
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  const png_uint_32 width = png_get_image_width(png, info);
  const png_uint_32 height = png_get_image_height(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  const int color_type = png_get_color_type(png, info);
  const InputLimits& limits = GlobalInputLimits();
  if (width == 0 || height == 0 || width > limits.max_side || height > limits.max_side ||
      static_cast<std::int64_t>(width) * height > limits.max_pixels) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw IoError(path, "image size " + std::to_string(width) + "x" + std::to_string(height) +
                            " is empty or exceeds the input limits");
  }
  if (color_type != PNG_COLOR_TYPE_GRAY) {
    png_destroy_read_struct(&png, &info, nullptr);
    throw IoError(path, "expected a single-channel (grey) PNG, got colour type " +
                            std::to_string(color_type));
  }
  if (bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (bit_depth == 16) png_set_swap(png);  // PNG is big-endian; we want host order (x86: little)
  png_read_update_info(png, info);
  const std::size_t row_bytes = png_get_rowbytes(png, info);
  image = Image16(static_cast<int>(width), static_cast<int>(height));
  row.resize(row_bytes);
  for (png_uint_32 r = 0; r < height; ++r) {
    png_read_row(png, row.data(), nullptr);
    std::uint16_t* out = image.data.data() + static_cast<std::size_t>(r) * width;
    if (bit_depth == 16) {
      std::memcpy(out, row.data(), static_cast<std::size_t>(width) * 2);
    } else {
      for (png_uint_32 c = 0; c < width; ++c) out[c] = row[c];
    }
  }
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
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

}  // namespace planeslam::datasets
