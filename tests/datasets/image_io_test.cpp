#include "planeslam/datasets/image_io.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/input_limits.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;

using test::ErrorOf;

// --- A minimal PNG encoder (stored deflate blocks), independent of the code under test. -------

std::uint32_t Crc32(const std::string& bytes) {
  std::uint32_t c = 0xffffffffu;
  for (unsigned char b : bytes) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}

void PutBe32(std::string* s, std::uint32_t v) {
  for (int k = 3; k >= 0; --k) s->push_back(static_cast<char>((v >> (8 * k)) & 0xff));
}

void Chunk(std::string* png, const std::string& type, const std::string& data) {
  PutBe32(png, static_cast<std::uint32_t>(data.size()));
  const std::string body = type + data;
  png->append(body);
  PutBe32(png, Crc32(body));
}

// Grey PNG of the given bit depth; `raw` holds the filtered-free scanlines without filter bytes.
std::string MakeGreyPng(std::uint32_t width, std::uint32_t height, int bit_depth,
                        const std::string& raw_rows, std::size_t row_bytes, int color_type = 0) {
  std::string png = "\x89PNG\r\n\x1a\n";
  std::string ihdr;
  PutBe32(&ihdr, width);
  PutBe32(&ihdr, height);
  ihdr.push_back(static_cast<char>(bit_depth));
  ihdr.push_back(static_cast<char>(color_type));
  ihdr.append(std::string(3, '\0'));  // deflate, adaptive filters, no interlace
  Chunk(&png, "IHDR", ihdr);
  if (row_bytes > 0) {
    std::string scan;
    for (std::size_t r = 0; r * row_bytes < raw_rows.size(); ++r) {
      scan.push_back('\0');  // filter type None
      scan.append(raw_rows, r * row_bytes, row_bytes);
    }
    std::string z = "\x78\x01";  // zlib header, no dictionary
    for (std::size_t i = 0; i < scan.size() || i == 0; i += 65535) {
      const std::size_t len = std::min<std::size_t>(65535, scan.size() - i);
      z.push_back(i + len >= scan.size() ? 1 : 0);  // BFINAL, BTYPE = stored
      z.push_back(static_cast<char>(len & 0xff));
      z.push_back(static_cast<char>(len >> 8));
      z.push_back(static_cast<char>(~len & 0xff));
      z.push_back(static_cast<char>((~len >> 8) & 0xff));
      z.append(scan, i, len);
    }
    std::uint32_t a = 1, b = 0;  // Adler-32
    for (unsigned char c : scan) {
      a = (a + c) % 65521;
      b = (b + a) % 65521;
    }
    PutBe32(&z, (b << 16) | a);
    Chunk(&png, "IDAT", z);
  }
  Chunk(&png, "IEND", "");
  return png;
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

TEST(ImageIo, Png16RoundTripsEveryValue) {
  const auto dir = test::ScratchDir();
  Image16 image(37, 23);
  std::mt19937 rng(3);
  for (auto& v : image.data) v = static_cast<std::uint16_t>(rng());
  image.data[0] = 0;
  image.data[1] = 65535;
  WritePng16((dir / "a.png").string(), image);
  const Image16 back = ReadPng16((dir / "a.png").string());
  EXPECT_EQ(back.width, 37);
  EXPECT_EQ(back.height, 23);
  EXPECT_EQ(back.data, image.data);
}

TEST(ImageIo, IndependentlyEncoded16And8BitGrey) {
  const auto dir = test::ScratchDir();
  // 16-bit big-endian samples 0x0102, 0xfffe, 0, 0x1388 (5000).
  const std::string raw16("\x01\x02\xff\xfe\x00\x00\x13\x88", 8);
  WriteBytes(dir / "g16.png", MakeGreyPng(2, 2, 16, raw16, 4));
  const Image16 a = ReadPng16((dir / "g16.png").string());
  EXPECT_EQ(a.data, (std::vector<std::uint16_t>{0x0102, 0xfffe, 0, 5000}));
  // 8-bit samples are widened to their value (not scaled).
  WriteBytes(dir / "g8.png", MakeGreyPng(3, 1, 8, std::string("\x00\x7f\xff", 3), 3));
  EXPECT_EQ(ReadPng16((dir / "g8.png").string()).data, (std::vector<std::uint16_t>{0, 127, 255}));
}

TEST(ImageIo, BadFilesAreIoErrorsNamingTheFile) {
  const auto dir = test::ScratchDir();
  const std::string missing = (dir / "missing.png").string();
  EXPECT_EQ(ErrorOf([&] { ReadPng16(missing); }), missing + ": no such file");
  WriteBytes(dir / "text.png", "hello, not a png");
  EXPECT_EQ(ErrorOf([&] { ReadPng16((dir / "text.png").string()); }),
            (dir / "text.png").string() + ": not a PNG file");
  EXPECT_EQ(ErrorOf([&] { ReadPng16(dir.string()); }), dir.string() + ": not a regular file");
  // Truncated: a real 16-bit PNG cut in half, and cut inside the header.
  Image16 image(64, 48);
  for (std::size_t i = 0; i < image.data.size(); ++i)
    image.data[i] = static_cast<std::uint16_t>(i * 37);
  const fs::path cut = dir / "cut.png";
  WritePng16(cut.string(), image);
  fs::resize_file(cut, fs::file_size(cut) / 2);
  std::string msg = ErrorOf([&] { ReadPng16(cut.string()); });
  EXPECT_EQ(msg.rfind(cut.string() + ": corrupt or truncated PNG", 0), 0u) << msg;
  fs::resize_file(cut, 20);
  msg = ErrorOf([&] { ReadPng16(cut.string()); });
  EXPECT_EQ(msg.rfind(cut.string() + ": corrupt or truncated PNG", 0), 0u) << msg;
  // A flipped byte in the compressed data (CRC mismatch).
  WritePng16(cut.string(), image);
  std::string bytes;
  {
    std::ifstream in(cut, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes[bytes.size() / 2] ^= 0x55;
  WriteBytes(cut, bytes);
  msg = ErrorOf([&] { ReadPng16(cut.string()); });
  EXPECT_EQ(msg.rfind(cut.string() + ": corrupt or truncated PNG", 0), 0u) << msg;
  // Colour image.
  WritePngRgb((dir / "rgb.png").string(), ImageRgb8(4, 4));
  EXPECT_EQ(
      ErrorOf([&] { ReadPng16((dir / "rgb.png").string()); }),
      (dir / "rgb.png").string() + ": expected a single-channel (grey) PNG, got colour type 2");
}

TEST(ImageIo, EveryTruncationIsIoError) {
  const auto dir = test::ScratchDir();
  Image16 image(9, 7);
  for (std::size_t i = 0; i < image.data.size(); ++i)
    image.data[i] = static_cast<std::uint16_t>(i * 977);
  WritePng16((dir / "a.png").string(), image);
  std::ifstream in(dir / "a.png", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  EXPECT_EQ(DecodePng16(bytes, "a.png").data, image.data);
  for (std::size_t len = 0; len < bytes.size(); ++len) {
    // IEND (the last 12 bytes) carries no pixels; libpng may accept a file cut inside it.
    if (len >= bytes.size() - 12) continue;
    EXPECT_THROW(DecodePng16(bytes.substr(0, len), "a.png"), IoError) << len;
  }
}

TEST(ImageIo, HugeHeaderIsRefusedBeforeAllocating) {
  const auto dir = test::ScratchDir();
  // IHDR claims 10^6 x 10^6 = 10^12 pixels, with only two bytes of image data behind it.
  WriteBytes(dir / "huge.png", MakeGreyPng(1000000, 1000000, 16, "ab", 2));
  EXPECT_EQ(ErrorOf([&] { ReadPng16((dir / "huge.png").string()); }),
            (dir / "huge.png").string() +
                ": image size 1000000x1000000 is empty or exceeds the input limits");
  // The PNG maximum (2^31 - 1) a side, too.
  WriteBytes(dir / "max.png", MakeGreyPng(0x7fffffff, 2, 16, "ab", 2));
  EXPECT_NE(
      ErrorOf([&] { ReadPng16((dir / "max.png").string()); }).find("exceeds the input limits"),
      std::string::npos);
  // The limits are the knob: a 64x48 image is refused under a 1000-pixel limit.
  WritePng16((dir / "ok.png").string(), Image16(64, 48));
  const InputLimits saved = GlobalInputLimits();
  GlobalInputLimits().max_pixels = 1000;
  const std::string msg = ErrorOf([&] { ReadPng16((dir / "ok.png").string()); });
  GlobalInputLimits() = saved;
  EXPECT_EQ(msg,
            (dir / "ok.png").string() + ": image size 64x48 is empty or exceeds the input limits");
  EXPECT_EQ(ReadPng16((dir / "ok.png").string()).width, 64);
}

}  // namespace
}  // namespace planeslam::datasets
