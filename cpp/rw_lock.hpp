// A reader/writer lock that lets a waiting writer in. glibc's rwlock prefers readers, so a
// steady stream of layer and query readers would starve insertion forever.
#pragma once

#include <mutex>
#include <shared_mutex>

namespace layerpilot {

class WriterPreferringLock {
 public:
  void lock() {
    std::lock_guard gate(gate_);  // new readers wait here while a writer waits for the lock
    rw_.lock();
  }
  void unlock() { rw_.unlock(); }
  void lock_shared() {
    { std::lock_guard gate(gate_); }
    rw_.lock_shared();
  }
  void unlock_shared() { rw_.unlock_shared(); }

 private:
  std::mutex gate_;
  std::shared_mutex rw_;
};

}  // namespace layerpilot
