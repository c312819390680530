// A server-streaming reactor whose work runs on its own thread: long builds
// (model training, controller building) that stream progress messages. The
// worker's messages are queued and written one at a time; the call finishes
// with the worker's status once the queue is drained. Cancellation (client
// gone or a failed write) is visible to the worker through cancelled().
//
//   class TrainReactor final : public WorkerWriteReactor<v1::TrainResponse> {
//     TrainReactor(...) { if (!TakeSlot(&counter, limit, "max_...")) return; StartWorker([this] { return Run(); }); }
//   };
//
// A call that is one function and a slot needs no class of its own:
// SlotWorkerReactor (below).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string_view>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "common/grpc/call_slot.h"
#include "common/grpc/status_mapping.h"
#include "common/status/status.h"

namespace kinemo {

template <typename Response>
class WorkerWriteReactor : public grpc::ServerWriteReactor<Response> {
 public:
  void OnWriteDone(bool ok) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      queue_.pop_front();
      if (!ok) {
        cancelled_ = true;
        queue_.clear();
      }
      if (!queue_.empty()) {
        this->StartWrite(&queue_.front());
      } else {
        writing_ = false;
        MaybeFinishLocked();
      }
    }
    space_.notify_all();
  }
  void OnCancel() override { cancelled_ = true; }
  void OnDone() override {
    if (worker_.joinable()) worker_.join();
    delete this;
  }

 protected:
  // Counts this call in `running` unless `limit` calls already run; else
  // finishes it with RESOURCE_EXHAUSTED naming `option` and returns false.
  bool TakeSlot(std::atomic<int>* running, int limit, std::string_view option, std::string_view what) {
    if (!slot_.Take(running, limit)) {
      FinishWith(absl::ResourceExhaustedError(kinemo::StrCat(option, ": ", limit, " ", what, " are running")));
      return false;
    }
    return true;
  }
  // Runs `work` on the worker thread; its status ends the call (the slot is
  // released before the client can see the end).
  void StartWorker(std::function<Status()> work) {
    worker_ = std::thread([this, work = std::move(work)] {
      const Status status = work();
      slot_.Release();
      FinishWith(status);
    });
  }
  // Queues a message (dropped once the call is cancelled or finished).
  void Enqueue(Response r) {
    std::lock_guard<std::mutex> lock(mu_);
    if (cancelled_ || finished_) return;
    queue_.push_back(std::move(r));
    if (!writing_) {
      writing_ = true;
      this->StartWrite(&queue_.front());
    }
  }
  // Queues a message once fewer than `max_queued` wait to be written: a
  // worker that sends a large result (a long motion in pieces) holds a few
  // messages at a time, at the pace the client reads. False (the message
  // dropped) once the call is cancelled or finished.
  bool EnqueueAndWait(Response r, std::size_t max_queued) {
    std::unique_lock<std::mutex> lock(mu_);
    // Cancellation is seen within 100 ms (OnCancel does not take the lock).
    while (!cancelled_ && !finished_ && queue_.size() >= max_queued) {
      space_.wait_for(lock, std::chrono::milliseconds(100));
    }
    if (cancelled_ || finished_) return false;
    queue_.push_back(std::move(r));
    if (!writing_) {
      writing_ = true;
      this->StartWrite(&queue_.front());
    }
    return true;
  }
  void FinishWith(const Status& status) {
    std::lock_guard<std::mutex> lock(mu_);
    final_ = status;
    done_ = true;
    MaybeFinishLocked();
  }
  bool cancelled() const { return cancelled_.load(); }

 private:
  void MaybeFinishLocked() {
    if (done_ && !writing_ && !finished_) {
      finished_ = true;
      this->Finish(ToGrpcStatus(final_));
    }
  }

  std::thread worker_;
  CallSlot slot_;
  std::mutex mu_;
  std::condition_variable space_;  // a queued message was written
  std::deque<Response> queue_;
  bool writing_ = false, done_ = false, finished_ = false;
  std::atomic<bool> cancelled_{false};
  Status final_;
};

// A server-streaming call that is one function on a worker thread, admitted
// by a slot of `running` (TakeSlot: RESOURCE_EXHAUSTED naming `option` when
// `limit` run). `work` sends its messages with the sender it is given, which
// waits while `max_queued` wait to be written and returns false (the message
// dropped) once the client went away; its status ends the call, the slot
// free before the client hears it.
template <typename Response>
class SlotWorkerReactor final : public WorkerWriteReactor<Response> {
 public:
  using Sender = std::function<bool(Response)>;
  SlotWorkerReactor(std::atomic<int>* running, int limit, std::string_view option, std::string_view what,
                    std::size_t max_queued, std::function<Status(const Sender&)> work) {
    if (!this->TakeSlot(running, limit, option, what)) return;
    this->StartWorker([this, max_queued, work = std::move(work)] {
      return work([this, max_queued](Response r) { return this->EnqueueAndWait(std::move(r), max_queued); });
    });
  }
};

}  // namespace kinemo
