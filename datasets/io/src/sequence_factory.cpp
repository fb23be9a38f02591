#include "planeslam/datasets/sequence_factory.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "planeslam/datasets/depth_image.hpp"
#include "planeslam/datasets/errors.hpp"
#include "planeslam/datasets/file_sequence.hpp"
#include "planeslam/datasets/kitti_scan.hpp"
#include "planeslam/datasets/tum_sequence.hpp"

namespace planeslam::datasets {

namespace fs = std::filesystem;

namespace {

std::string LowerExtension(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

}  // namespace

std::string ToString(SequenceLayout layout) {
  switch (layout) {
    case SequenceLayout::kTum:
      return "tum";
    case SequenceLayout::kIclNuim:
      return "icl";
    case SequenceLayout::kPcdFolder:
      return "pcd";
    case SequenceLayout::kKittiBin:
      return "kitti";
  }
  return "unknown";
}

SequenceLayout DetectLayout(const std::string& folder) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) throw IoError(folder, "no such folder");
  if (!fs::is_directory(folder, ec)) throw IoError(folder, "not a folder (expected a sequence)");
  const fs::path dir(folder);
  if (fs::is_regular_file(dir / "depth.txt", ec)) return SequenceLayout::kTum;
  if (fs::is_regular_file(dir / "associations.txt", ec)) return SequenceLayout::kIclNuim;
  // KITTI odometry sequence folder: velodyne/*.bin beside times.txt (and poses.txt, calib.txt).
  if (fs::is_directory(dir / "velodyne", ec)) return SequenceLayout::kKittiBin;
  bool any = false, pcd = false, bin = false;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    any = true;
    if (!entry.is_regular_file(ec)) continue;
    const std::string ext = LowerExtension(entry.path());
    pcd = pcd || ext == ".pcd";
    bin = bin || ext == ".bin";
  }
  if (ec) throw IoError(folder, "cannot list folder (" + ec.message() + ")");
  if (pcd) return SequenceLayout::kPcdFolder;
  if (bin) return SequenceLayout::kKittiBin;
  if (!any) throw IoError(folder, "folder is empty");
  throw IoError(folder,
                "no known layout (expected depth.txt, associations.txt, velodyne/, *.pcd or *.bin "
                "files)");
}

std::unique_ptr<Sequence> OpenSequence(const std::string& folder, const SensorConfig& config) {
  switch (DetectLayout(folder)) {
    case SequenceLayout::kTum:
      return OpenTumSequence(folder, config);
    case SequenceLayout::kIclNuim:
      return OpenIclSequence(folder, config);
    case SequenceLayout::kPcdFolder:
      return OpenPcdFolder(folder, config);
    case SequenceLayout::kKittiBin:
      return OpenKittiFolder(folder, config);
  }
  throw IoError(folder, "unknown layout");
}

Frame LoadSingleFrame(const std::string& path, const SensorConfig& config) {
  config.ValidateOrThrow();
  std::error_code ec;
  if (!fs::exists(path, ec)) throw IoError(path, "no such file");
  if (!fs::is_regular_file(path, ec)) throw IoError(path, "not a regular file");
  const std::string ext = LowerExtension(path);
  Frame frame;
  frame.source = path;
  if (ext == ".png") {
    frame.cloud = ReadDepthCloud(path, config.EffectiveIntrinsics(), config.depth_scale,
                                 config.min_depth, config.max_depth);
    return frame;
  }
  if (ext == ".bin") {
    frame.cloud = ReadKittiRangeImage(path, config);
    return frame;
  }
  if (ext == ".pcd") {
    frame.cloud = ReadOrganizedPcd(path, config);
    return frame;
  }
  throw IoError(path, "unknown file type '" + ext + "' (expected .png, .pcd or .bin)");
}

}  // namespace planeslam::datasets
