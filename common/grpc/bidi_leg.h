// One client-side bidirectional stream on the callback API, driven by an
// owner that runs several such streams (and perhaps a server stream) under
// one mutex: a "leg" of a pipeline. It queues what the owner sends and
// writes it one message at a time, reads until the server ends the call,
// half-closes once the queue is written after Close(), and tells the owner
// each message and the end. No thread of its own.
//
//   auto* leg = new ClientBidiLeg<Req, Resp>({keep, &mu, on_message, on_done, pump}, std::move(context));
//   stub->async()->Method(leg->context(), leg);
//   leg->Send(first);
//   leg->Begin();
//   ... under mu: leg->Send(r); leg->Pump();  ... leg->Close();
//
// Threading: every method but the reactions runs under the owner's mutex;
// every reaction takes it and calls the owner's hooks under it, then
// `pump` (the owner calls Pump() on its legs there). A hold keeps the call
// open while the owner may write from its other reactions; it is released
// with WritesDone, on cancellation, or when the call broke.
//
// Lifetime: the leg deletes itself after its end. The owner hears the end
// (on_done) once gRPC is done with the call and the leg's ClientContext is
// gone (destroyed under the owner's mutex, so a Cancel() under that mutex
// never meets a dying context): after on_done the owner must forget the
// leg, and no gRPC object of the leg outlives it (an owner that finishes its
// own call after its last leg's end leaves nothing of the legs behind).
//
// Progress (for an idle timeout): the leg owes progress while a write is in
// flight, from a Send(r, owes=true) until the next message read, and after
// Close() until its end; stalled_since() says since when.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <utility>

#include <grpcpp/grpcpp.h>
#include <grpcpp/support/client_callback.h>

namespace kinemo {

template <typename Req, typename Resp>
class ClientBidiLeg final : public ::grpc::ClientBidiReactor<Req, Resp> {
 public:
  using Clock = std::chrono::steady_clock;
  struct Owner {
    std::shared_ptr<void> keep;  // kept alive until on_done has returned
    std::mutex* mu = nullptr;    // held for every hook
    std::function<void(Resp&)> on_message;
    // The call's status, and whether Close() had been called (an end before
    // it is the server's own). The leg is gone once it returns.
    std::function<void(const ::grpc::Status&, bool closed)> on_done;
    std::function<void()> pump;  // after every reaction
  };

  ClientBidiLeg(Owner owner, std::unique_ptr<::grpc::ClientContext> context)
      : owner_(std::move(owner)), context_(std::move(context)) {}
  ::grpc::ClientContext* context() { return context_.get(); }
  // After the stub's async() call has bound this reactor (and the first
  // messages are queued): starts the call.
  void Begin() {
    this->StartRead(&in_);
    this->AddHold();
    this->StartCall();
  }
  // Queues a message (dropped once closing). `owes`: the peer owes an answer.
  void Send(Req r, bool owes = false) {
    if (closing_) return;
    out_.push_back(std::move(r));
    if (owes) Owe();
  }
  // WritesDone once the queued messages are written; the peer then owes its end.
  void Close() {
    closing_ = true;
    Owe();
  }
  bool closing() const { return closing_; }
  // Since when the leg owes progress (none: Clock::time_point::max()).
  Clock::time_point stalled_since() const {
    return std::min(writing_ ? write_since_ : Clock::time_point::max(), owed_since_);
  }
  // Cancels the call; its end still comes (on_done).
  void Cancel() {
    cancelled_ = true;
    if (context_ != nullptr) context_->TryCancel();
    ReleaseHold();
  }
  std::size_t queued() const { return out_.size(); }
  // Starts the next write, or the half-close once everything is written.
  void Pump() {
    if (cancelled_ || broken_) return;
    if (!writing_ && !out_.empty()) {
      writing_ = true;
      write_since_ = Clock::now();
      this->StartWrite(&out_.front());
    } else if (closing_ && !writing_ && out_.empty() && !writes_done_) {
      writes_done_ = true;
      this->StartWritesDone();
      ReleaseHold();
    }
  }

 private:
  void OnReadDone(bool ok) override {
    std::lock_guard<std::mutex> l(*owner_.mu);
    if (ok) {
      // Progress: nothing owed (but the end, once closed).
      owed_since_ = closing_ ? Clock::now() : Clock::time_point::max();
      owner_.on_message(in_);
      if (!cancelled_) this->StartRead(&in_);
    } else {
      // The server ended the call (its status is on the way): let OnDone come.
      broken_ = true;
      ReleaseHold();
    }
    owner_.pump();
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> l(*owner_.mu);
    writing_ = false;
    out_.pop_front();
    if (!ok) {  // the call is over; OnDone tells why
      broken_ = true;
      ReleaseHold();
    }
    owner_.pump();
  }
  void OnDone(const ::grpc::Status& status) override {
    Owner owner = std::move(owner_);  // destroyed last: may free the owner
    {
      std::lock_guard<std::mutex> l(*owner.mu);
      context_.reset();
      owner.on_done(status, closing_);
      owner.pump();
    }
    delete this;
  }
  void ReleaseHold() {
    if (hold_released_) return;
    hold_released_ = true;
    this->RemoveHold();
  }
  void Owe() { owed_since_ = std::min(owed_since_, Clock::now()); }

  Owner owner_;
  std::unique_ptr<::grpc::ClientContext> context_;
  Resp in_;
  std::deque<Req> out_;  // front: being written
  bool writing_ = false, closing_ = false, writes_done_ = false;
  bool cancelled_ = false, broken_ = false, hold_released_ = false;
  Clock::time_point write_since_;                            // the write in flight started
  Clock::time_point owed_since_ = Clock::time_point::max();  // the oldest answer owed
};

}  // namespace kinemo
