#include "planeslam/datasets/atomic_file.hpp"

#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {

AtomicOutputFile::AtomicOutputFile(std::string path, bool binary)
    : path_(std::move(path)),
      tmp_path_(path_ + ".tmp." + std::to_string(static_cast<long>(::getpid()))) {
  stream_.open(tmp_path_, binary ? std::ios::binary | std::ios::out | std::ios::trunc
                                 : std::ios::out | std::ios::trunc);
  if (!stream_) throw IoError(path_, "cannot create file");
}

AtomicOutputFile::~AtomicOutputFile() {
  if (!committed_) {
    stream_.close();
    std::error_code ec;
    std::filesystem::remove(tmp_path_, ec);
  }
}

void AtomicOutputFile::Commit() {
  stream_.flush();
  const bool ok = static_cast<bool>(stream_);
  stream_.close();
  if (!ok || stream_.fail()) throw IoError(path_, "write failed (disk full?)");
  if (std::rename(tmp_path_.c_str(), path_.c_str()) != 0) {
    throw IoError(path_, "cannot rename temporary file into place");
  }
  committed_ = true;
}

void WriteFileAtomic(const std::string& path, const std::string& bytes) {
  AtomicOutputFile out(path, /*binary=*/true);
  out.stream().write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.Commit();
}

}  // namespace planeslam::datasets
