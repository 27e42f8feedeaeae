#include "cell/dpr7545/transport.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <new>

#include "cell/dpr7545/sim_control.hpp"

namespace cell::dpr7545 {
namespace {

std::string errno_text(int err) { return std::strerror(err); }

class HeapTransport final : public Transport {
 public:
  HeapTransport() : memory_(new (std::align_val_t{64}) std::byte[kWindowSize]()) {}
  ~HeapTransport() override { ::operator delete[](memory_, std::align_val_t{64}); }
  std::span<std::byte> window() noexcept override { return {memory_, kWindowSize}; }
  const std::string& describe() const noexcept override { return name_; }

 private:
  std::byte* memory_;
  std::string name_ = "heap";
};

/// A mapping of kWindowSize bytes of a file descriptor (shm segment or /dev/mem).
class MappedTransport final : public Transport {
 public:
  MappedTransport(void* memory, std::string describe, std::string shm_name, bool unlink_on_close,
                  dev_t device, ino_t inode)
      : memory_(memory),
        describe_(std::move(describe)),
        shm_name_(std::move(shm_name)),
        unlink_(unlink_on_close),
        device_(device),
        inode_(inode) {}
  ~MappedTransport() override {
    ::munmap(memory_, kWindowSize);
    if (unlink_) {
      // Only unlink the name if it still refers to our segment (a newer simulator may have
      // replaced it after declaring ours stale).
      if (!replaced()) {
        ::shm_unlink(shm_name_.c_str());
      }
    }
  }
  std::span<std::byte> window() noexcept override {
    return {static_cast<std::byte*>(memory_), kWindowSize};
  }
  const std::string& describe() const noexcept override { return describe_; }
  bool replaced() const noexcept override {
    if (shm_name_.empty()) {
      return false;
    }
    const int fd = ::shm_open(shm_name_.c_str(), O_RDONLY, 0);
    if (fd < 0) {
      return true;  // the name is gone: whoever opens it next gets another segment
    }
    struct stat st {};
    const bool same = ::fstat(fd, &st) == 0 && st.st_dev == device_ && st.st_ino == inode_;
    ::close(fd);
    return !same;
  }

 private:
  void* memory_;
  std::string describe_;
  std::string shm_name_;
  bool unlink_;
  dev_t device_;
  ino_t inode_;
};

bool process_alive(std::uint32_t pid) {
  if (pid == 0) {
    return false;
  }
  return ::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
}

/// The pid recorded in an existing segment `name`, 0 when none or unreadable.
std::uint32_t recorded_owner(const std::string& name) {
  const int fd = ::shm_open(name.c_str(), O_RDWR, 0);
  if (fd < 0) {
    return 0;
  }
  struct stat st {};
  std::uint32_t pid = 0;
  if (::fstat(fd, &st) == 0 && static_cast<std::size_t>(st.st_size) >= kWindowSize) {
    void* memory = ::mmap(nullptr, kWindowSize, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (memory != MAP_FAILED) {
      const SimControl control({static_cast<std::byte*>(memory), kWindowSize});
      pid = control.valid() ? control.owner_pid() : 0;
      ::munmap(memory, kWindowSize);
    }
  }
  ::close(fd);
  return pid;
}

}  // namespace

std::unique_ptr<Transport> make_heap_transport() { return std::make_unique<HeapTransport>(); }

Status validate_shm_name(std::string_view name) {
  if (name.size() < 2 || name.size() > 255) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("shm name '{}' must have 2 to 255 characters", name)};
  }
  if (name.front() != '/' || name.find('/', 1) != std::string_view::npos) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("shm name '{}' must start with '/' and contain no other '/'", name)};
  }
  return ok_status();
}

Result<std::unique_ptr<Transport>> create_shm(const std::string& name) {
  CELL_TRY(validate_shm_name(name));
  int fd = ::shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0660);
  if (fd < 0 && errno == EEXIST) {
    const std::uint32_t owner = recorded_owner(name);
    if (owner != 0 && owner != static_cast<std::uint32_t>(::getpid()) && process_alive(owner)) {
      return Error{Errc::kIo, fmt::format("shm segment '{}' is in use by process {} (another "
                                          "cell-sim-7545?): choose another shm_name",
                                          name, owner)};
    }
    ::shm_unlink(name.c_str());  // stale: its simulator is gone
    fd = ::shm_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0660);
  }
  if (fd < 0) {
    return Error{Errc::kIo, fmt::format("cannot create shm segment '{}': {}", name,
                                        errno_text(errno))};
  }
  if (::ftruncate(fd, static_cast<off_t>(kWindowSize)) != 0) {
    const int err = errno;
    ::close(fd);
    ::shm_unlink(name.c_str());
    return Error{Errc::kIo, fmt::format("cannot size shm segment '{}' to {} bytes: {}", name,
                                        kWindowSize, errno_text(err))};
  }
  struct stat st {};
  (void)::fstat(fd, &st);
  void* memory = ::mmap(nullptr, kWindowSize, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int err = errno;
  ::close(fd);
  if (memory == MAP_FAILED) {
    ::shm_unlink(name.c_str());
    return Error{Errc::kIo, fmt::format("cannot map shm segment '{}': {}", name, errno_text(err))};
  }
  SimControl({static_cast<std::byte*>(memory), kWindowSize})
      .initialise(static_cast<std::uint32_t>(::getpid()));
  return std::unique_ptr<Transport>(std::make_unique<MappedTransport>(
      memory, "shm:" + name, name, true, st.st_dev, st.st_ino));
}

Result<std::unique_ptr<Transport>> open_shm(const std::string& name) {
  CELL_TRY(validate_shm_name(name));
  const int fd = ::shm_open(name.c_str(), O_RDWR, 0);
  if (fd < 0) {
    if (errno == ENOENT) {
      return Error{Errc::kNotReady, fmt::format("shm segment '{}' does not exist: is "
                                                "cell-sim-7545 running with this shm_name?",
                                                name)};
    }
    return Error{Errc::kIo, fmt::format("cannot open shm segment '{}': {}", name,
                                        errno_text(errno))};
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || static_cast<std::size_t>(st.st_size) < kWindowSize) {
    ::close(fd);
    return Error{Errc::kIo, fmt::format("shm segment '{}' has {} bytes, the DPR window needs {}",
                                        name, static_cast<long long>(st.st_size), kWindowSize)};
  }
  void* memory = ::mmap(nullptr, kWindowSize, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int err = errno;
  ::close(fd);
  if (memory == MAP_FAILED) {
    return Error{Errc::kIo, fmt::format("cannot map shm segment '{}': {}", name, errno_text(err))};
  }
  return std::unique_ptr<Transport>(std::make_unique<MappedTransport>(
      memory, "shm:" + name, name, false, st.st_dev, st.st_ino));
}

Result<std::unique_ptr<Transport>> open_physical(const std::string& device,
                                                 std::uint64_t base_address) {
  const long page = ::sysconf(_SC_PAGESIZE);
  if (page <= 0 || base_address % static_cast<std::uint64_t>(page) != 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("physical base address 0x{:x} is not page-aligned ({} bytes)",
                             base_address, page)};
  }
  const int fd = ::open(device.c_str(), O_RDWR | O_SYNC);
  if (fd < 0) {
    const int err = errno;
    return Error{Errc::kIo,
                 fmt::format("cannot open {}: {} (the physical DPR transport maps the interface "
                             "card at 0x{:x} and needs root or CAP_SYS_RAWIO)",
                             device, errno_text(err), base_address)};
  }
  void* memory = ::mmap(nullptr, kWindowSize, PROT_READ | PROT_WRITE, MAP_SHARED, fd,
                        static_cast<off_t>(base_address));
  const int err = errno;
  ::close(fd);
  if (memory == MAP_FAILED) {
    return Error{Errc::kIo,
                 fmt::format("cannot map {} bytes of {} at 0x{:x}: {} (a kernel with "
                             "CONFIG_STRICT_DEVMEM only allows the legacy ISA range)",
                             kWindowSize, device, base_address, errno_text(err))};
  }
  return std::unique_ptr<Transport>(std::make_unique<MappedTransport>(
      memory, fmt::format("physical:{}@0x{:x}", device, base_address), std::string(), false, 0,
      0));
}

}  // namespace cell::dpr7545
