#include "planeslam/datasets/atomic_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "planeslam/datasets/errors.hpp"

namespace planeslam::datasets {
namespace {

// Table of temporary files being written, readable from a signal handler: fixed-size slots of
// plain char arrays guarded by an atomic "in use" flag (no allocation, no locks).
constexpr int kMaxActive = 64;
constexpr std::size_t kMaxPath = 4096;
std::atomic<bool> g_slot_used[kMaxActive];
char g_slot_path[kMaxActive][kMaxPath];

int ClaimSlot(const std::string& path) {
  if (path.size() + 1 > kMaxPath) return -1;
  for (int i = 0; i < kMaxActive; ++i) {
    bool expected = false;
    if (!g_slot_used[i].load() && g_slot_used[i].compare_exchange_strong(expected, true)) {
      std::memcpy(g_slot_path[i], path.c_str(), path.size() + 1);
      return i;
    }
  }
  return -1;  // more than kMaxActive files open at once: the file is still written atomically
}

void ReleaseSlot(int slot) {
  if (slot >= 0) g_slot_used[slot].store(false);
}

}  // namespace

void RemoveActiveTempFilesFromSignalHandler() {
  for (int i = 0; i < kMaxActive; ++i) {
    if (g_slot_used[i].load()) ::unlink(g_slot_path[i]);
  }
}

AtomicOutputFile::AtomicOutputFile(std::string path, bool binary)
    : path_(std::move(path)),
      tmp_path_(path_ + ".tmp." + std::to_string(static_cast<long>(::getpid()))) {
  stream_.open(tmp_path_, binary ? std::ios::binary | std::ios::out | std::ios::trunc
                                 : std::ios::out | std::ios::trunc);
  if (!stream_) throw IoError(path_, "cannot create file");
  slot_ = ClaimSlot(tmp_path_);
}

AtomicOutputFile::~AtomicOutputFile() {
  if (!committed_) {
    stream_.close();
    std::error_code ec;
    std::filesystem::remove(tmp_path_, ec);
  }
  ReleaseSlot(slot_);
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
  ReleaseSlot(slot_);
  slot_ = -1;
}

void WriteFileAtomic(const std::string& path, const std::string& bytes) {
  AtomicOutputFile out(path, /*binary=*/true);
  out.stream().write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.Commit();
}

}  // namespace planeslam::datasets
