// `kinemo preview IN.bvh -o OUT.png`: a contact sheet of stick figures, to
// look at synthesised motion without a 3-D engine.
#include <fstream>
#include <iostream>
#include <memory>
#include <string>

#include "common/image/skeleton_sheet.h"
#include "common/motion/bvh.h"
#include "services/cli/commands.h"

namespace kinemo::cli {

void RegisterPreviewCommands(CLI::App& app) {
  struct Args {
    std::string in, out;
    image::SheetOptions sheet;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("preview", "draw a BVH clip as a contact sheet of stick figures (PNG)");
  cmd->add_option("bvh", a->in, "BVH file")->required();
  cmd->add_option("-o,--out", a->out, "PNG file to write")->required();
  cmd->add_option("--panels", a->sheet.panels, "frames shown, evenly spaced")->capture_default_str();
  cmd->add_option("--columns", a->sheet.columns, "panels per row")->capture_default_str();
  cmd->add_option("--panel-px", a->sheet.panel_px, "panel side in pixels")->capture_default_str();
  cmd->add_flag("--side", a->sheet.side_view, "side view (depth horizontal) instead of front view");
  cmd->callback([a] {
    auto fail = [](const Status& s) {
      std::cerr << "kinemo preview: " << std::string(s.message()) << "\n";
      const bool bad = s.code() == absl::StatusCode::kInvalidArgument || s.code() == absl::StatusCode::kNotFound;
      throw CliExit{bad ? 2 : 1};
    };
    auto clip = motion::ReadBvhFile(a->in);
    if (!clip.ok()) fail(clip.status());
    auto png = image::RenderSkeletonSheetPng(*clip, a->sheet);
    if (!png.ok()) fail(png.status());
    std::ofstream out(a->out, std::ios::binary | std::ios::trunc);
    out.write(png->data(), static_cast<std::streamsize>(png->size()));
    if (!out) fail(absl::PermissionDeniedError(a->out + ": cannot write"));
    std::cout << a->out << ": " << std::min(a->sheet.panels, clip->num_frames()) << " frames of "
              << clip->duration_s() << " s\n";
  });
}

}  // namespace kinemo::cli
