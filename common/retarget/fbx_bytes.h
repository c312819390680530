// FBX at the byte level, for fbx.cc: what is checked before assimp's parser
// trusts a file, and the repair of what assimp's binary writer gets wrong.
// Internal to kinemo_retarget.
#pragma once

#include <map>
#include <string>
#include <string_view>

#include "common/status/status.h"

namespace kinemo::retarget {

// What assimp's FBX parser trusts, checked first (binary: record and
// property bounds, array sizes, nesting; ASCII: "*N" array counts).
// INVALID_ARGUMENT naming `name` and the byte offset.
Status CheckFbxStructure(std::string_view bytes, const std::string& name);

// Whether `bytes` start like an FBX file (the binary header, or an ASCII
// FBXHeaderExtension near the start).
bool HasFbxHeader(std::string_view bytes);

// assimp's binary FBX output with the null records its writer leaves out and
// GlobalSettings' properties set from `settings` (name -> value).
StatusOr<std::string> FixExportedFbx(std::string_view bytes, const std::map<std::string, double>& settings);

}  // namespace kinemo::retarget
