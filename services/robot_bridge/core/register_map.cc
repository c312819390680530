#include "services/robot_bridge/core/register_map.h"

namespace kinemo::robot {

std::string_view EmotionName(Emotion e) {
  switch (e) {
    case Emotion::kNeutral: return "neutral";
    case Emotion::kHappy: return "happy";
    case Emotion::kAngry: return "angry";
  }
  return "unknown";
}

std::optional<Emotion> EmotionFromName(std::string_view name) {
  for (uint16_t i = 0; i < kEmotionCount; ++i) {
    if (EmotionName(static_cast<Emotion>(i)) == name) return static_cast<Emotion>(i);
  }
  return std::nullopt;
}

std::string_view RobotStateName(RobotState s) {
  switch (s) {
    case RobotState::kFollowing: return "following";
    case RobotState::kSwitching: return "switching";
    case RobotState::kAutonomous: return "autonomous";
    case RobotState::kSleeping: return "sleeping";
  }
  return "unknown";
}

std::string_view SimFaultName(SimFault f) {
  switch (f) {
    case SimFault::kNone: return "none";
    case SimFault::kDelay: return "delay";
    case SimFault::kDrop: return "drop";
    case SimFault::kBusy: return "busy";
    case SimFault::kCorrupt: return "corrupt";
    case SimFault::kSilent: return "silent";
    case SimFault::kNoise: return "noise";
  }
  return "unknown";
}

std::optional<SimFault> SimFaultFromName(std::string_view name) {
  for (uint16_t i = 0; i < kSimFaultCount; ++i) {
    if (SimFaultName(static_cast<SimFault>(i)) == name) return static_cast<SimFault>(i);
  }
  return std::nullopt;
}

}  // namespace kinemo::robot
