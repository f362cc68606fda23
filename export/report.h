// report.html: one self-contained page (images, data and the charting
// library inlined; it opens offline) about a workspace: the stages with
// their times and summaries; the capture (frames with their landmarks and
// mask outlines); the cameras round the head; tracking (residuals,
// blendshape curves); training (loss and held-out PSNR against wall time);
// the held-out scores with the best and worst frames; the videos export
// wrote beside it; and accuracy against time from `headforge bench train`
// (its rows in the workspace) and from `headforge bench calibrate` and
// `headforge bench track` (their results.json files).
#pragma once

#include <string>
#include <vector>

#include "core/fs.h"
#include "core/status.h"

namespace headforge {

struct ReportOptions {
  // Chart.js's UMD build (chart.umd.min.js), inlined for the plots; empty or
  // missing: the page says so and shows the tables and images alone.
  std::string chart_js;
  std::vector<std::string> exported;  // files beside the report, relative to it (listed, and the videos shown)
  // results.json files `headforge bench calibrate` and `bench track` wrote;
  // one that cannot be read is said on the page.
  std::vector<fs::path> bench_results;
};

// Writes `out_dir`/report.html about `workspace`. `*note` says what the page
// lacks (no charting library, no trained model), empty when nothing.
Status WriteReport(const fs::path& workspace, const fs::path& out_dir, const ReportOptions& options,
                   std::string* note);

}  // namespace headforge
