// A contact sheet of a motion clip: evenly spaced frames drawn as stick
// figures (bones between joints, end sites, the hands and head marked), front
// view (x right, y up; the skeleton's own units), each panel centred on the
// root's horizontal position so that walking stays in view. For previews of
// synthesised motion without a 3-D engine.
#pragma once

#include <string>

#include "common/motion/skeleton.h"
#include "common/status/status.h"

namespace kinemo::image {

struct SheetOptions {
  int panels = 12;          // frames shown (at most the clip's frames)
  int columns = 6;          // panels per row
  int panel_px = 220;       // square panel side in pixels
  bool side_view = false;   // draw z (depth) horizontally instead of x
};

// Renders the sheet as a BGR image, encoded as PNG bytes. INVALID_ARGUMENT
// for an empty clip or bad options.
StatusOr<std::string> RenderSkeletonSheetPng(const motion::Clip& clip, const SheetOptions& options = {});

}  // namespace kinemo::image
