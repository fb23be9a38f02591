#include "planeslam/datasets/pcd_io.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/file_sequence.hpp"
#include "planeslam/datasets/sequence_factory.hpp"
#include "test_support.hpp"

namespace planeslam::datasets {
namespace {

namespace fs = std::filesystem;

using test::ErrorOf;

bool Contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

std::string Header(const std::string& fields, const std::string& size, const std::string& type,
                   const std::string& count, int w, int h, long points, const std::string& data) {
  return "# .PCD v0.7\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " + size + "\nTYPE " + type +
         "\nCOUNT " + count + "\nWIDTH " + std::to_string(w) + "\nHEIGHT " + std::to_string(h) +
         "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + std::to_string(points) + "\nDATA " + data + "\n";
}

template <class T>
void Append(std::string* s, T v) {
  s->append(reinterpret_cast<const char*>(&v), sizeof(T));
}

// Valid LZF made of literal runs only (at most 32 bytes each).
std::string LzfLiterals(const std::string& raw) {
  std::string out;
  for (std::size_t i = 0; i < raw.size(); i += 32) {
    const std::size_t len = std::min<std::size_t>(32, raw.size() - i);
    out.push_back(static_cast<char>(len - 1));
    out.append(raw, i, len);
  }
  return out;
}

// A 3x2 cloud with fields "intensity(u8) x(f32) y(f64) z(f32) normal(f32 x3)": point i is
// (i, 2i, 10 + i) with point 4 invalid (NaN z).
struct Toy {
  static constexpr int kW = 3, kH = 2, kN = 6;
  static double X(int i) { return i; }
  static double Y(int i) { return 2.0 * i; }
  static double Z(int i) { return i == 4 ? std::nan("") : 10.0 + i; }
};
const char* kToyFields = "intensity x y z normal";
const char* kToySize = "1 4 8 4 4";
const char* kToyType = "U F F F F";
const char* kToyCount = "1 1 1 1 3";

std::string ToyBinaryData() {
  std::string d;
  for (int i = 0; i < Toy::kN; ++i) {
    Append<std::uint8_t>(&d, static_cast<std::uint8_t>(7 * i));
    Append<float>(&d, static_cast<float>(Toy::X(i)));
    Append<double>(&d, Toy::Y(i));
    Append<float>(&d, static_cast<float>(Toy::Z(i)));
    for (int k = 0; k < 3; ++k) Append<float>(&d, 0.5f);
  }
  return d;
}

std::string ToySoaData() {
  std::string d;
  for (int i = 0; i < Toy::kN; ++i) Append<std::uint8_t>(&d, static_cast<std::uint8_t>(7 * i));
  for (int i = 0; i < Toy::kN; ++i) Append<float>(&d, static_cast<float>(Toy::X(i)));
  for (int i = 0; i < Toy::kN; ++i) Append<double>(&d, Toy::Y(i));
  for (int i = 0; i < Toy::kN; ++i) Append<float>(&d, static_cast<float>(Toy::Z(i)));
  for (int i = 0; i < Toy::kN * 3; ++i) Append<float>(&d, 0.5f);
  return d;
}

std::string ToyHeader(const std::string& data, long points = Toy::kN) {
  return Header(kToyFields, kToySize, kToyType, kToyCount, Toy::kW, Toy::kH, points, data);
}

void ExpectToy(const OrganizedCloud& c, double scale = 1.0) {
  ASSERT_EQ(c.width, Toy::kW);
  ASSERT_EQ(c.height, Toy::kH);
  for (int i = 0; i < Toy::kN; ++i) {
    if (i == 4) {
      EXPECT_FALSE(c.IsValid(i));
      EXPECT_TRUE(std::isnan(c.points[i].x()));
      continue;
    }
    EXPECT_FLOAT_EQ(c.points[i].x(), static_cast<float>(Toy::X(i) * scale));
    EXPECT_FLOAT_EQ(c.points[i].y(), static_cast<float>(Toy::Y(i) * scale));
    EXPECT_FLOAT_EQ(c.points[i].z(), static_cast<float>(Toy::Z(i) * scale));
  }
}

TEST(PcdIo, BinaryMixedFieldTypes) {
  ExpectToy(ParsePcd(ToyHeader("binary") + ToyBinaryData(), "toy.pcd"));
  ExpectToy(ParsePcd(ToyHeader("binary") + ToyBinaryData(), "toy.pcd", 0.01), 0.01);
}

TEST(PcdIo, BinaryCompressedStoresFieldsSoA) {
  const std::string raw = ToySoaData();
  std::string d;
  const std::string lzf = LzfLiterals(raw);
  Append<std::uint32_t>(&d, static_cast<std::uint32_t>(lzf.size()));
  Append<std::uint32_t>(&d, static_cast<std::uint32_t>(raw.size()));
  ExpectToy(ParsePcd(ToyHeader("binary_compressed") + d + lzf, "toy.pcd"));
  // PCL pads the file with zeros after the payload; that is accepted.
  ExpectToy(ParsePcd(ToyHeader("binary_compressed") + d + lzf + std::string(100, '\0'), "t"));
}

TEST(PcdIo, AsciiWithNanAndCounts) {
  std::string text = ToyHeader("ascii");
  for (int i = 0; i < Toy::kN; ++i) {
    text += std::to_string(7 * i) + " " + std::to_string(Toy::X(i)) + " " +
            std::to_string(Toy::Y(i)) + " " + (i == 4 ? "nan" : std::to_string(Toy::Z(i))) +
            " 0.5 0.5 0.5\n";
  }
  ExpectToy(ParsePcd(text, "toy.pcd"));
}

TEST(PcdIo, TinyAsciiAndBinaryFilesRoundTrip) {
  const auto dir = test::ScratchDir();
  // Ascii written by hand, then read back from disk.
  WriteBytes(dir / "a.pcd", Header("x y z", "4 4 4", "F F F", "1 1 1", 2, 2, 4, "ascii") +
                                "0 0 1\n1 0 1\nnan nan nan\n1 1 2.5\n");
  const OrganizedCloud a = ReadPcd((dir / "a.pcd").string());
  EXPECT_EQ(a.CountValid(), 3u);
  EXPECT_FLOAT_EQ(a.at(1, 1).z(), 2.5f);
  EXPECT_FLOAT_EQ(a.at(0, 1).x(), 1.0f);
  // Our binary writer, read back bit for bit (with and without rgb).
  OrganizedCloud c(5, 4);
  for (int i = 0; i < 20; ++i) {
    if (i % 7 != 3) c.points[i] = Eigen::Vector3f(0.1f * i, -0.2f * i, 1.0f + 0.01f * i);
  }
  WritePcd((dir / "b.pcd").string(), c);
  const OrganizedCloud b = ReadPcd((dir / "b.pcd").string());
  ASSERT_EQ(b.width, 5);
  ASSERT_EQ(b.height, 4);
  for (int i = 0; i < 20; ++i) {
    EXPECT_EQ(b.IsValid(i), c.IsValid(i));
    if (c.IsValid(i)) {
      EXPECT_EQ(b.points[i], c.points[i]);
    }
  }
  std::vector<std::uint32_t> rgb(20, 0x00ff8000u);
  WritePcd((dir / "c.pcd").string(), c, &rgb);
  const PcdHeader h = ParsePcdHeader(
      std::string(
          std::istreambuf_iterator<char>(std::ifstream(dir / "c.pcd", std::ios::binary).rdbuf()),
          {}),
      "c");
  EXPECT_EQ(h.FieldIndex("rgb"), 3);
  EXPECT_EQ(h.point_bytes, 16u);
  EXPECT_EQ(ReadPcd((dir / "c.pcd").string()).CountValid(), c.CountValid());
  EXPECT_TRUE(fs::is_empty(dir) == false);
  for (const auto& e : fs::directory_iterator(dir)) {
    EXPECT_EQ(e.path().string().find(".tmp."), std::string::npos);  // atomic write left nothing
  }
}

TEST(PcdIo, LzfKnownAnswers) {
  // Literal "ab", then a back reference of length 4 at distance 2 (overlapping copy).
  const char short_ref[] = {0x01, 'a', 'b', static_cast<char>(2 << 5), 0x01};
  EXPECT_EQ(LzfDecompress(short_ref, sizeof(short_ref), 6, "t"), "ababab");
  // Long form: length field 7 + extra byte 3 -> 7 + 3 + 2 = 12 bytes at distance 1.
  const char long_ref[] = {0x00, 'z', static_cast<char>(7 << 5), 0x03, 0x00};
  EXPECT_EQ(LzfDecompress(long_ref, sizeof(long_ref), 13, "t"), std::string(13, 'z'));
  // Reference before the start of the output, truncated literal, wrong total size.
  const char bad_ref[] = {0x00, 'a', static_cast<char>(2 << 5), 0x05};
  EXPECT_TRUE(Contains(ErrorOf([&] { LzfDecompress(bad_ref, sizeof(bad_ref), 5, "f.pcd"); }),
                       "f.pcd: corrupt LZF data"));
  const char short_lit[] = {0x05, 'a'};
  EXPECT_TRUE(Contains(ErrorOf([&] { LzfDecompress(short_lit, sizeof(short_lit), 6, "f"); }),
                       "literal run past the end"));
  EXPECT_TRUE(Contains(ErrorOf([&] { LzfDecompress(short_ref, sizeof(short_ref), 9, "f"); }),
                       "decompresses to 6 bytes, the header announces 9"));
  EXPECT_TRUE(Contains(ErrorOf([&] { LzfDecompress(short_ref, sizeof(short_ref), 4, "f"); }),
                       "more than 4 bytes"));
}

TEST(PcdIo, LyingHeadersAreIoErrorsNamingTheFile) {
  const std::string data = ToyBinaryData();
  // POINTS disagrees with WIDTH x HEIGHT.
  EXPECT_EQ(ErrorOf([&] { ParsePcd(ToyHeader("binary", 7) + data, "f.pcd"); }),
            "f.pcd: header says POINTS 7 but WIDTH x HEIGHT is 3x2 = 6");
  // Data shorter / longer than announced.
  EXPECT_TRUE(
      Contains(ErrorOf([&] { ParsePcd(ToyHeader("binary") + data.substr(0, 50), "f.pcd"); }),
               "f.pcd: truncated: header announces 6 points"));
  EXPECT_EQ(ErrorOf([&] { ParsePcd(ToyHeader("binary") + data + "xyz", "f.pcd"); }),
            "f.pcd: 3 bytes of data beyond the 6 points the header announces");
  // WIDTH x HEIGHT larger than the data (POINTS consistent with it).
  EXPECT_TRUE(Contains(
      ErrorOf([&] {
        ParsePcd(Header(kToyFields, kToySize, kToyType, kToyCount, 3, 3, 9, "binary") + data,
                 "f.pcd");
      }),
      "f.pcd: truncated"));
  // Compressed sizes that disagree.
  const std::string raw = ToySoaData();
  const std::string lzf = LzfLiterals(raw);
  std::string words;
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(lzf.size()));
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(raw.size() + 4));
  EXPECT_TRUE(
      Contains(ErrorOf([&] { ParsePcd(ToyHeader("binary_compressed") + words + lzf, "f.pcd"); }),
               "f.pcd: compressed block says"));
  words.clear();
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(lzf.size() + 10));
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(raw.size()));
  EXPECT_TRUE(
      Contains(ErrorOf([&] { ParsePcd(ToyHeader("binary_compressed") + words + lzf, "f.pcd"); }),
               "f.pcd: truncated: compressed block of"));
  words.clear();
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(lzf.size() - 5));
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(raw.size()));
  EXPECT_TRUE(
      Contains(ErrorOf([&] { ParsePcd(ToyHeader("binary_compressed") + words + lzf, "f.pcd"); }),
               "f.pcd: corrupt LZF data"));
  // Unknown DATA kind, missing field, bad header words.
  EXPECT_TRUE(Contains(ErrorOf([&] { ParsePcd(ToyHeader("binary_lz4") + data, "f.pcd"); }),
                       "unknown DATA kind 'binary_lz4'"));
  EXPECT_EQ(ErrorOf([&] {
              ParsePcd(Header("x y", "4 4", "F F", "1 1", 1, 2, 2, "ascii") + "1 2\n3 4\n",
                       "f.pcd");
            }),
            "f.pcd: PCD has no field 'z' (FIELDS must include x y z)");
  EXPECT_TRUE(Contains(ErrorOf([&] {
                         ParsePcd(Header("x y z", "4 4", "F F F", "1 1 1", 1, 2, 2, "ascii"),
                                  "f.pcd");
                       }),
                       "one entry per field"));
  EXPECT_TRUE(Contains(ErrorOf([&] {
                         ParsePcd(Header("x y z", "4 4 3", "F F F", "1 1 1", 1, 2, 2, "ascii"),
                                  "f.pcd");
                       }),
                       "SIZE must be 1, 2, 4 or 8"));
  EXPECT_EQ(ErrorOf([&] { ParsePcd("hello world\n", "f.pcd"); }),
            "f.pcd:1: unknown header keyword 'hello'");
  EXPECT_EQ(ErrorOf([&] { ParsePcd("", "f.pcd"); }),
            "f.pcd: not a PCD file (no DATA line in the header)");
  // Ascii with too few / too many points or values.
  const std::string h2 = Header("x y z", "4 4 4", "F F F", "1 1 1", 1, 2, 2, "ascii");
  EXPECT_EQ(
      ErrorOf([&] { ParsePcd(h2 + "1 2 3\n", "f.pcd"); }),
      "f.pcd: truncated: 6 bytes of ascii data cannot hold the 2 points the header announces");
  EXPECT_EQ(ErrorOf([&] { ParsePcd(h2 + "1.5 2.5 3.5\n", "f.pcd"); }),
            "f.pcd: truncated: header announces 2 points, ascii data has 1");
  EXPECT_EQ(ErrorOf([&] { ParsePcd(h2 + "1 2 3\n1 2 3\n1 2 3\n", "f.pcd"); }),
            "f.pcd: more ascii data than the 2 points the header announces");
  EXPECT_EQ(ErrorOf([&] { ParsePcd(h2 + "1 2 3\n1.5 2.5\n", "f.pcd"); }),
            "f.pcd: ascii point 1 has 2 values, the header announces 3");
  EXPECT_EQ(ErrorOf([&] { ParsePcd(h2 + "1 2 3\n1 2 x\n", "f.pcd"); }),
            "f.pcd: ascii point 1: not a number 'x'");
}

TEST(PcdIo, HugeHeaderIsRefusedBeforeAllocating) {
  // 10^12 points: refused by the limits with no attempt to allocate.
  const std::string h =
      Header("x y z", "4 4 4", "F F F", "1 1 1", 1000000, 1000000, 1000000000000L, "binary");
  EXPECT_EQ(ErrorOf([&] { ParsePcd(h, "huge.pcd"); }),
            "huge.pcd: cloud of 1000000x1000000 points exceeds the input limits");
  const std::string flat =
      Header("x y z", "4 4 4", "F F F", "1 1 1", 1000000000, 1000, 1000000000000L, "binary");
  EXPECT_TRUE(Contains(ErrorOf([&] { ParsePcd(flat, "huge.pcd"); }), "exceeds the input limits"));
  // Within the limits but far beyond the data: refused before the cloud is allocated.
  const std::string big_ascii =
      Header("x y z", "4 4 4", "F F F", "1 1 1", 8000, 8000, 64000000, "ascii") + "1 2 3\n";
  EXPECT_EQ(ErrorOf([&] { ParsePcd(big_ascii, "big.pcd"); }),
            "big.pcd: truncated: 6 bytes of ascii data cannot hold the 64000000 points the header "
            "announces");
  std::string words;
  Append<std::uint32_t>(&words, 10);
  Append<std::uint32_t>(&words, 4000u * 4000u * 12u);
  const std::string big_lzf =
      Header("x y z", "4 4 4", "F F F", "1 1 1", 4000, 4000, 16000000, "binary_compressed") +
      words + std::string(10, '\0');
  EXPECT_EQ(ErrorOf([&] { ParsePcd(big_lzf, "big.pcd"); }),
            "big.pcd: compressed block of 10 bytes cannot expand to the 192000000 bytes the header "
            "needs");
  const std::string line =
      Header("x y z", "4 4 4", "F F F", "1 1 1", 2000000000, 1, 2000000000, "binary");
  EXPECT_TRUE(Contains(ErrorOf([&] { ParsePcd(line, "huge.pcd"); }), "exceeds the input limits"));
}

TEST(PcdIo, MissingFileAndUnorganizedCloud) {
  const auto dir = test::ScratchDir();
  EXPECT_EQ(ErrorOf([&] { ReadPcd((dir / "none.pcd").string()); }),
            (dir / "none.pcd").string() + ": no such file");
  WriteBytes(dir / "u.pcd", Header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, 3, "ascii") +
                                "1 2 3\n1 2 3\n1 2 3\n");
  EXPECT_EQ(ReadPcd((dir / "u.pcd").string()).width, 3);
  EXPECT_TRUE(Contains(ErrorOf([&] { LoadSingleFrame((dir / "u.pcd").string(), SensorConfig{}); }),
                       "cloud is not organized"));
}

// Every prefix and many single-byte corruptions of valid files either parse or throw IoError:
// no crash, no other exception (run under ASan/UBSan in CI).
TEST(PcdIo, TruncatedAndCorruptedBytesNeverCrash) {
  const std::string raw = ToySoaData();
  const std::string lzf = LzfLiterals(raw);
  std::string words;
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(lzf.size()));
  Append<std::uint32_t>(&words, static_cast<std::uint32_t>(raw.size()));
  std::string ascii = ToyHeader("ascii");
  for (int i = 0; i < Toy::kN; ++i) ascii += std::to_string(i) + " 1 2 3 0.5 0.5 0.5\n";
  const std::vector<std::string> files = {ToyHeader("binary") + ToyBinaryData(),
                                          ToyHeader("binary_compressed") + words + lzf, ascii};
  std::mt19937 rng(11);
  std::size_t parsed = 0, refused = 0;
  for (const std::string& file : files) {
    for (std::size_t len = 0; len <= file.size(); ++len) {
      try {
        ParsePcd(file.substr(0, len), "t.pcd");
        ++parsed;
      } catch (const IoError&) {
        ++refused;
      }
    }
    for (int trial = 0; trial < 2000; ++trial) {
      std::string bad = file;
      bad[rng() % bad.size()] = static_cast<char>(rng());
      try {
        ParsePcd(bad, "t.pcd");
        ++parsed;
      } catch (const IoError&) {
        ++refused;
      }
    }
  }
  EXPECT_GT(refused, 0u);
  EXPECT_GT(parsed, 0u);
}

// ---------------------------------------------------------------------------------------------
// Real organized clouds.

// In a Kinect cloud x/z is an affine function of the column and y/z of the row: checks that the
// SoA payload is decoded into the right cells.
void ExpectPinholeGrid(const OrganizedCloud& c) {
  double sum_u = 0, sum_r = 0, sum_uu = 0, sum_ur = 0;
  std::size_t n = 0;
  for (int v = 0; v < c.height; v += 7) {
    for (int u = 0; u < c.width; u += 3) {
      const auto& p = c.at(v, u);
      if (!OrganizedCloud::IsValid(p)) continue;
      const double r = p.x() / p.z();
      sum_u += u;
      sum_r += r;
      sum_uu += double(u) * u;
      sum_ur += u * r;
      ++n;
    }
  }
  ASSERT_GT(n, 1000u);
  const double slope = (n * sum_ur - sum_u * sum_r) / (n * sum_uu - sum_u * sum_u);
  const double offset = (sum_r - slope * sum_u) / n;
  EXPECT_GT(slope, 1.0 / 700);  // 1/fx for a Kinect (fx ~ 525-580 px)
  EXPECT_LT(slope, 1.0 / 450);
  double worst = 0;
  for (int v = 0; v < c.height; v += 7) {
    for (int u = 0; u < c.width; u += 3) {
      const auto& p = c.at(v, u);
      if (!OrganizedCloud::IsValid(p)) continue;
      worst = std::max(worst, std::abs(p.x() / p.z() - (slope * u + offset)));
    }
  }
  EXPECT_LT(worst, 2.0 * slope);  // within two pixels everywhere
}

TEST(PcdIo, OrganizedKinectCloudsAreBinaryCompressed640x480) {
  PLANESLAM_REQUIRE_DATA();
  const fs::path dir = test::DataDir() / "organized_pcd";
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 7u);
  std::vector<std::string> names = {"office1.pcd", "frame_20121214T142255.814212.pcd",
                                    "frame_20121214T142256.068683.pcd",
                                    "frame_20121214T142256.332395.pcd"};
  for (const auto& name : names) {
    SCOPED_TRACE(name);
    const std::string path = (dir / name).string();
    std::ifstream in(path, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), {});
    EXPECT_EQ(ParsePcdHeader(bytes, path).data, "binary_compressed");
    const OrganizedCloud c = ParsePcd(bytes, path);
    EXPECT_EQ(c.width, 640);
    EXPECT_EQ(c.height, 480);
    EXPECT_GT(c.CountValid(), 640u * 480 / 2);
    for (const auto& p : c.points) {
      if (OrganizedCloud::IsValid(p)) {
        ASSERT_TRUE(p.z() > 0.2f && p.z() < 12.0f) << p.transpose();
      }
    }
    ExpectPinholeGrid(c);
  }
}

TEST(PcdIo, FrameFolderUsesStampsFromNames) {
  PLANESLAM_REQUIRE_DATA();
  const auto dir = test::ScratchDir();
  for (const char* n : {"frame_20121214T142256.332395.pcd", "frame_20121214T142255.814212.pcd"}) {
    fs::create_symlink(test::DataDir() / "organized_pcd" / n, dir / n);
  }
  const auto seq = OpenSequence(dir.string(), SensorConfig{});
  ASSERT_EQ(seq->Size(), 2u);
  EXPECT_NEAR(seq->Timestamp(1) - seq->Timestamp(0), 0.518183, 1e-6);
  // 2012-12-14 14:22:55.814212 UTC
  EXPECT_NEAR(seq->Timestamp(0), 1355494975.814212, 1e-4);
}

TEST(PcdIo, LaserScanInCentimetresReadsInMetres) {
  PLANESLAM_REQUIRE_DATA();
  SensorConfig config;
  config.unit_scale = 0.01;
  config.pcd_model = "spherical";
  const Frame f =
      LoadSingleFrame((test::DataDir() / "laser_scans" / "scan000.pcd").string(), config);
  EXPECT_EQ(f.cloud.width, 513);
  EXPECT_EQ(f.cloud.height, 633);
  EXPECT_EQ(f.cloud.model, SensorModel::kSpherical);
  std::vector<float> ranges;
  for (const auto& p : f.cloud.points) {
    if (OrganizedCloud::IsValid(p)) ranges.push_back(p.norm());
  }
  ASSERT_GT(ranges.size(), 513u * 633 / 2);
  std::nth_element(ranges.begin(), ranges.begin() + ranges.size() / 2, ranges.end());
  const float median = ranges[ranges.size() / 2];
  std::printf("scan000: %zu valid points, median range %.2f m\n", ranges.size(), median);
  EXPECT_GT(median, 1.0f);  // a house scanned from inside/outside: metres, not centimetres
  EXPECT_LT(median, 30.0f);
}

}  // namespace
}  // namespace planeslam::datasets
