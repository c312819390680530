#include "services/coordinator/idle_watchdog.h"

#include <algorithm>

namespace kinemo::coordinator {

Watchdog::Watchdog(Clock::duration period) : period_(period) {
  thread_ = std::thread([this] { Run(); });
}

Watchdog::~Watchdog() { Stop(); }

Watchdog::Clock::duration Watchdog::PeriodFor(double idle_s) {
  const double s = std::clamp(idle_s / 10, 0.01, 0.25);
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

void Watchdog::Add(Check check) {
  std::lock_guard<std::mutex> l(mu_);
  if (!stopping_) added_.push_back(std::move(check));
}

void Watchdog::Stop() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
    added_.clear();
  }
  cv_.notify_all();
  if (thread_.joinable() && thread_.get_id() != std::this_thread::get_id()) thread_.join();
}

void Watchdog::Run() {
  std::vector<Check> checks;
  std::unique_lock<std::mutex> l(mu_);
  while (!stopping_) {
    cv_.wait_for(l, period_, [&] { return stopping_; });
    if (stopping_) break;
    std::move(added_.begin(), added_.end(), std::back_inserter(checks));
    added_.clear();
    l.unlock();
    const Clock::time_point now = Clock::now();
    checks.erase(std::remove_if(checks.begin(), checks.end(), [&](Check& c) { return !c(now); }), checks.end());
    l.lock();
  }
  l.unlock();
  checks.clear();  // (may release the last reference to a stream)
}

IdleGuard::IdleGuard(Watchdog* watchdog, grpc::ClientContext* context, double idle_s) {
  if (watchdog == nullptr || !(idle_s > 0)) return;
  state_ = std::make_shared<State>();
  state_->context = context;
  Touch();
  const auto idle = std::chrono::duration_cast<Watchdog::Clock::duration>(std::chrono::duration<double>(idle_s));
  watchdog->Add([state = state_, idle](Watchdog::Clock::time_point now) {
    std::lock_guard<std::mutex> l(state->mu);
    if (state->context == nullptr) return false;
    const Watchdog::Clock::time_point last{Watchdog::Clock::duration(state->last_ns.load())};
    if (now - last < idle) return true;
    state->expired = true;
    state->context->TryCancel();
    return false;
  });
}

IdleGuard::~IdleGuard() {
  if (!state_) return;
  std::lock_guard<std::mutex> l(state_->mu);
  state_->context = nullptr;
}

void IdleGuard::Touch() {
  if (state_) state_->last_ns.store(Watchdog::Clock::now().time_since_epoch().count());
}

bool IdleGuard::expired() const {
  if (!state_) return false;
  std::lock_guard<std::mutex> l(state_->mu);
  return state_->expired;
}

}  // namespace kinemo::coordinator
