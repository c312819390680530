// An admission slot: one of at most `limit` calls of a kind running at once
// (max_concurrent_streams, max_concurrent_chunked, ...). Take() counts the
// call unless `limit` already run (then nothing is counted); Release()
// frees it once, whoever calls it first (also the destructor).
//
// Release before the client can hear the call's end (before Finish, or in a
// synchronous handler before it returns): a client that starts its next call
// on hearing the last one's end must not be refused by that finished call.
#pragma once

#include <atomic>

namespace kinemo {

class CallSlot {
 public:
  CallSlot() = default;
  CallSlot(const CallSlot&) = delete;
  CallSlot& operator=(const CallSlot&) = delete;
  ~CallSlot() { Release(); }
  // False (nothing counted) when `limit` calls already hold one.
  bool Take(std::atomic<int>* running, int limit) {
    if (running->fetch_add(1) >= limit) {
      running->fetch_sub(1);
      return false;
    }
    running_.store(running);
    return true;
  }
  void Release() {
    if (std::atomic<int>* r = running_.exchange(nullptr)) r->fetch_sub(1);
  }
  bool held() const { return running_.load() != nullptr; }

 private:
  std::atomic<std::atomic<int>*> running_{nullptr};
};

}  // namespace kinemo
