// `planeslam bench io`: see bench_io.hpp.
#include "bench_io.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>

#include "exit_codes.hpp"
#include "planeslam/datasets/atomic_file.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/image_io.hpp"
#include "planeslam/datasets/kitti_scan.hpp"
#include "planeslam/datasets/pcd_io.hpp"

namespace planeslam::app::bench {
namespace {

namespace ds = planeslam::datasets;
namespace fs = std::filesystem;

std::vector<std::string> FilesWithExtension(const fs::path& dir, const std::string& ext) {
  std::vector<std::string> files;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return files;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    if (e.path().extension() == ext) files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw IoError(path, "cannot open file");
  std::string bytes(static_cast<std::size_t>(in.tellg()), '\0');
  in.seekg(0);
  if (!in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()))) {
    throw IoError(path, "read failed");
  }
  return bytes;
}

double Milliseconds(const std::function<void()>& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

/// Per-file medians summed over the files, divided by the file count: ms a file.
struct FormatResult {
  std::string format, folder;
  std::size_t files = 0;
  double read_ms = 0.0, reference_ms = 0.0, current_ms = 0.0;
  bool has_reference = false;
  std::size_t mismatches = 0;
};

FormatResult Measure(const std::string& format, const fs::path& folder, const std::string& ext,
                     int repeat, const std::function<void(const std::string&)>* reference,
                     const std::function<void(const std::string&)>& current,
                     const std::function<bool(const std::string&)>* agree) {
  FormatResult r;
  r.format = format;
  r.folder = folder.string();
  r.has_reference = reference != nullptr;
  for (const std::string& file : FilesWithExtension(folder, ext)) {
    std::string bytes;
    const double read_ms = Milliseconds([&] { bytes = ReadBytes(file); });
    std::vector<double> ref_times, cur_times;
    // Interleaved, so that both decoders see the same machine load.
    for (int k = 0; k < repeat; ++k) {
      if (reference) ref_times.push_back(Milliseconds([&] { (*reference)(bytes); }));
      cur_times.push_back(Milliseconds([&] { current(bytes); }));
    }
    if (agree && !(*agree)(bytes)) ++r.mismatches;
    r.read_ms += read_ms;
    r.reference_ms += Median(ref_times);
    r.current_ms += Median(cur_times);
    ++r.files;
  }
  if (r.files > 0) {
    r.read_ms /= r.files;
    r.reference_ms /= r.files;
    r.current_ms /= r.files;
  }
  return r;
}

}  // namespace

int RunIoBench(const IoBenchOptions& options) {
  const fs::path data(options.data_dir);
  const int repeat = std::max(1, options.repeat);
  const std::function<void(const std::string&)> png_reference = [](const std::string& b) {
    ds::DecodePng16WithLibpng(b, "bench.png");
  };
  const std::function<void(const std::string&)> png_current = [](const std::string& b) {
    ds::DecodePng16(b, "bench.png");
  };
  const std::function<bool(const std::string&)> png_agree = [](const std::string& b) {
    return ds::DecodePng16(b, "bench.png").data == ds::DecodePng16WithLibpng(b, "bench.png").data;
  };
  const std::function<void(const std::string&)> kitti = [](const std::string& b) {
    ds::ParseKittiScan(b, "bench.bin");
  };
  const std::function<void(const std::string&)> pcd = [](const std::string& b) {
    ds::ParsePcd(b, "bench.pcd");
  };
  std::vector<FormatResult> results;
  results.push_back(Measure("png16", data / "tum_fr3_structure_notexture_far" / "depth", ".png",
                            repeat, &png_reference, png_current, &png_agree));
  results.push_back(
      Measure("kitti-bin", data / "kitti_velodyne", ".bin", repeat, nullptr, kitti, nullptr));
  results.push_back(Measure("pcd", data / "organized_pcd", ".pcd", repeat, nullptr, pcd, nullptr));

  std::printf("%-10s %-52s %6s %9s %12s %11s %7s\n", "format", "folder", "files", "read ms",
              "libpng ms", "decode ms", "ratio");
  nlohmann::json j = nlohmann::json::array();
  std::size_t mismatches = 0;
  for (const FormatResult& r : results) {
    if (r.files == 0) {
      std::printf("%-10s %-52s (no files, skipped)\n", r.format.c_str(), r.folder.c_str());
      continue;
    }
    char ref[32] = "-", ratio[32] = "-";
    if (r.has_reference) {
      std::snprintf(ref, sizeof(ref), "%.3f", r.reference_ms);
      std::snprintf(ratio, sizeof(ratio), "%.2fx", r.reference_ms / r.current_ms);
    }
    std::printf("%-10s %-52s %6zu %9.3f %12s %11.3f %7s\n", r.format.c_str(), r.folder.c_str(),
                r.files, r.read_ms, ref, r.current_ms, ratio);
    nlohmann::json row = {{"format", r.format},        {"folder", r.folder},
                          {"files", r.files},          {"read_ms", r.read_ms},
                          {"decode_ms", r.current_ms}, {"repeat", repeat}};
    if (r.has_reference) {
      row["libpng_ms"] = r.reference_ms;
      row["ratio"] = r.reference_ms / r.current_ms;
      row["pixel_mismatches"] = r.mismatches;
    }
    j.push_back(row);
    mismatches += r.mismatches;
  }
  std::printf("ms a file: median of %d decodes of the bytes in memory, mean over the files; read "
              "= one read of the file\n",
              repeat);
  if (!options.json_path.empty()) ds::WriteFileAtomic(options.json_path, j.dump(2) + "\n");
  if (mismatches > 0) {
    std::cerr << "planeslam: error: " << mismatches
              << " PNG files decode differently with libpng and DecodePng16\n";
    return kExitError;
  }
  return kExitSuccess;
}

}  // namespace planeslam::app::bench
