#pragma once
/// Crash-safe output: write to "<path>.tmp.<pid>" and rename into place on Commit(), so a failed or
/// interrupted run never leaves a half-written file under the final name.
#include <fstream>
#include <string>

namespace planeslam::datasets {

class AtomicOutputFile {
 public:
  /// Opens the temporary file; throws IoError naming `path` when it cannot be created.
  explicit AtomicOutputFile(std::string path, bool binary = false);
  /// Removes the temporary file if Commit() was not reached.
  ~AtomicOutputFile();
  AtomicOutputFile(const AtomicOutputFile&) = delete;
  AtomicOutputFile& operator=(const AtomicOutputFile&) = delete;

  std::ostream& stream() { return stream_; }
  /// Flushes, closes and renames into place; throws IoError on any write failure.
  void Commit();
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::string tmp_path_;
  std::ofstream stream_;
  bool committed_ = false;
  int slot_ = -1;  ///< entry in the table of active temporary files (for signal handlers)
};

/// Unlinks every temporary file currently open by an AtomicOutputFile. Async-signal-safe: meant for
/// a signal handler that exits at once (a second Ctrl-C), so no partial file is left behind.
void RemoveActiveTempFilesFromSignalHandler();

/// Writes `bytes` to `path` atomically.
void WriteFileAtomic(const std::string& path, const std::string& bytes);

}  // namespace planeslam::datasets
