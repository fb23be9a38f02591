#pragma once
/// PNG images in and out. Reads take the grey 8/16-bit files cameras write through libdeflate and
/// everything else (and every file that path does not accept) through libpng, whose verdict and
/// messages stand. Reads validate size and bit depth and throw IoError naming the
/// file; writes go to a temporary name and are renamed into place (no half-written files).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace planeslam::datasets {

/// Single-channel 16-bit image (depth in sensor units, or plane labels), row-major.
struct Image16 {
  int width = 0;
  int height = 0;
  std::vector<std::uint16_t> data;
  Image16() = default;
  Image16(int w, int h) : width(w), height(h), data(static_cast<std::size_t>(w) * h, 0) {}
};

/// 8-bit RGB image, row-major, 3 bytes per pixel.
struct ImageRgb8 {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> data;
  ImageRgb8() = default;
  ImageRgb8(int w, int h) : width(w), height(h), data(static_cast<std::size_t>(w) * h * 3, 0) {}
};

/// Reads a single-channel PNG (16-bit, or 8-bit widened). Throws IoError on a missing, truncated
/// or corrupt file, a colour image, or a size above the configured limits.
Image16 ReadPng16(const std::string& path);
/// Decodes a PNG held in memory (as ReadPng16; `name` is used in messages). For fuzzing and for
/// callers that already hold the bytes.
Image16 DecodePng16(const std::string& bytes, const std::string& name);
/// The same decode with libpng alone: pixel for pixel what DecodePng16 gives (tests and
/// `planeslam bench io` compare the two).
Image16 DecodePng16WithLibpng(const std::string& bytes, const std::string& name);
/// Writes a 16-bit grey PNG atomically.
void WritePng16(const std::string& path, const Image16& image);
/// Writes an 8-bit RGB PNG atomically.
void WritePngRgb(const std::string& path, const ImageRgb8& image);

/// The colour every planeslam output gives plane label `id` (label images, previews, plane-map
/// meshes): golden-ratio hue steps, stable across runs; id <= 0 (no plane) is grey.
std::array<std::uint8_t, 3> LabelColour(int id);

}  // namespace planeslam::datasets
