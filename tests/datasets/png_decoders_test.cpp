// DecodePng16 (libdeflate for the common grey files, libpng for the rest) against libpng alone:
// the same pixels for every file, the same verdict and message for every damaged one.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/synthetic_sequence.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;

std::string FileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

/// Pixels, or the error message when the decoder throws.
struct Outcome {
  std::vector<std::uint16_t> pixels;
  int width = -1;
  std::string error;
  bool operator==(const Outcome& o) const {
    return pixels == o.pixels && width == o.width && error == o.error;
  }
};

template <typename Decode>
Outcome Run(Decode decode, const std::string& bytes) {
  Outcome out;
  try {
    Image16 image = decode(bytes, "x.png");
    out.pixels = std::move(image.data);
    out.width = image.width;
  } catch (const IoError& e) {
    out.error = e.what();
  }
  return out;
}

void ExpectSameOutcome(const std::string& bytes, const std::string& what) {
  const Outcome fast = Run(DecodePng16, bytes);
  const Outcome reference = Run(DecodePng16WithLibpng, bytes);
  EXPECT_TRUE(fast == reference) << what << ": '" << fast.error << "' vs '" << reference.error
                                 << "', " << fast.pixels.size() << " vs "
                                 << reference.pixels.size() << " pixels";
}

TEST(PngDecoders, EveryRealDepthFrameDecodesAsWithLibpng) {
  PLANESLAM_REQUIRE_DATA();
  std::vector<fs::path> files;
  for (const auto& dir : {test::DataDir() / "tum_fr3_structure_notexture_far" / "depth",
                          test::DataDir() / "depth_frames"}) {
    if (!fs::is_directory(dir)) continue;
    for (const auto& e : fs::directory_iterator(dir)) {
      if (e.path().extension() == ".png") files.push_back(e.path());
    }
  }
  if (files.empty()) GTEST_SKIP() << "no depth PNGs under " << test::DataDir();
  for (const auto& f : files) {
    const std::string bytes = FileBytes(f);
    const Image16 fast = DecodePng16(bytes, f.string());
    const Image16 reference = DecodePng16WithLibpng(bytes, f.string());
    ASSERT_EQ(fast.width, reference.width) << f;
    ASSERT_EQ(fast.height, reference.height) << f;
    ASSERT_EQ(fast.data, reference.data) << f;
  }
}

// Depth images of the built-in room and corridor as planeslam writes them (adaptive filters, so
// every filter type appears), and their damaged variants.
TEST(PngDecoders, RenderedDepthFramesAndTheirDamageDecodeAsWithLibpng) {
  const auto dir = test::ScratchDir();
  std::mt19937 rng(11);
  for (SceneKind scene : {SceneKind::kRoom, SceneKind::kCorridor}) {
    const SyntheticSequence sequence(SyntheticConfig::ForScene(scene));
    for (std::size_t i = 0; i < sequence.Size(); i += sequence.Size() / 4) {
      const SyntheticFrame frame = sequence.Generate(i);
      Image16 depth(frame.frame.cloud.width, frame.frame.cloud.height);
      for (std::size_t k = 0; k < depth.data.size(); ++k) {
        const float z = frame.true_range[k];
        depth.data[k] = std::isfinite(z) ? static_cast<std::uint16_t>(std::lround(z * 5000.0)) : 0;
      }
      const fs::path path = dir / "depth.png";
      WritePng16(path.string(), depth);
      const std::string bytes = FileBytes(path);
      EXPECT_EQ(DecodePng16(bytes, "x.png").data, depth.data);
      ExpectSameOutcome(bytes, "frame " + std::to_string(i));
      for (int k = 0; k < 6; ++k) {
        std::string damaged = bytes;
        damaged[8 + rng() % (bytes.size() - 8)] ^= static_cast<char>(1 << (rng() % 8));
        ExpectSameOutcome(damaged, "bit flip " + std::to_string(k));
        ExpectSameOutcome(bytes.substr(0, rng() % bytes.size()), "cut " + std::to_string(k));
      }
    }
  }
}

// A randomized family: sizes from 1 px to 400 x 160 (small images get a reduced zlib window and
// go to libpng), noise, gradients and runs, 8 and 16 bits; each with cuts and bit flips.
// Budget: no difference at all.
TEST(PngDecoders, RandomImagesAndTheirDamageDecodeAsWithLibpng) {
  const auto dir = test::ScratchDir();
  std::mt19937 rng(5);
  for (int draw = 0; draw < 60; ++draw) {
    const int w = 1 + static_cast<int>(rng() % 400), h = 1 + static_cast<int>(rng() % 160);
    Image16 image(w, h);
    const int mode = draw % 3;
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * w + c;
        image.data[i] = mode == 0   ? static_cast<std::uint16_t>(rng())
                        : mode == 1 ? static_cast<std::uint16_t>(1000 + 7 * r + 3 * c)
                                    : static_cast<std::uint16_t>((rng() % 8 == 0) ? rng() % 4000 : 0);
      }
    }
    const fs::path path = dir / "random.png";
    WritePng16(path.string(), image);
    const std::string bytes = FileBytes(path);
    EXPECT_EQ(DecodePng16(bytes, "x.png").data, image.data) << "draw " << draw;
    ExpectSameOutcome(bytes, "draw " + std::to_string(draw));
    for (int k = 0; k < 10; ++k) {
      std::string damaged = bytes;
      damaged[8 + rng() % (bytes.size() - 8)] ^= static_cast<char>(1 << (rng() % 8));
      ExpectSameOutcome(damaged, "draw " + std::to_string(draw) + " flip " + std::to_string(k));
      ExpectSameOutcome(bytes.substr(0, rng() % bytes.size()),
                        "draw " + std::to_string(draw) + " cut " + std::to_string(k));
    }
  }
}

}  // namespace
}  // namespace planeslam::datasets
