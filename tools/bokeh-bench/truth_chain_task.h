// truth_chain_task.h — bokeh-bench's truth-chain task (truth_chain_task.cpp).
#pragma once

#include "defocus_task.h"

#include <string>
#include <vector>

namespace bokeh_bench {

/// The truth-chain task's CSV columns: per scene and stage, the PSNR (tone-mapped, as
/// bench_common.h) against the geometric truth over the frame's interior and over the
/// disocclusion mask, the same over 4 x 4 block averages (independent noise 12 dB down),
/// the mask's size, the stage's time.
inline constexpr const char* kTruthChainCsvHeader
    = "scene,width,height,spp,threads,stage,frame_psnr_db,mask_psnr_db,frame_psnr_db_4x4,mask_psnr_db_4x4,mask_px,interior_px,seconds";

/// Run the chain on the built-in scenes (args.only: a subset) at args.width x args.height,
/// print a table, append CSV rows. False on an error, reported on stderr.
bool run_truth_chain_task(const BenchArgs& args, std::vector<std::string>& rows);

}  // namespace bokeh_bench
