// sequence.h — frame sequences on the command line, as oiiotool has them.
//
// An argument holding a frame pattern (`shot.#.exr`, `shot.@@@@.exr`, `shot.%04d.exr`,
// `shot.1-10#.exr`) makes the whole command line run once per frame, with the frame
// number substituted into every such argument. The frames come from `--frames SPEC`
// (`1-10`, `1-10x2`, `3,5,8-9`), else from a range written in the pattern, else from
// the files on disk that match the first pattern. `--framepadding N` sets the digits of
// '#' (oiiotool's meaning).
#pragma once

#include <string>
#include <vector>

namespace bokehtool {

struct FramePlan {
    std::vector<std::string> args;         ///< the command line less --frames SPEC
    std::vector<int> pattern_args;          ///< indices into args holding a pattern
    std::vector<std::string> normalized;    ///< printf form of each, e.g. "shot.%04d.exr"
    std::vector<int> frames;                ///< empty: not a sequence, run once
};

/// Build the plan from the arguments after the program name. False + `err` when a
/// pattern or --frames is malformed, or a pattern matches no file and no frame range
/// was given.
bool plan_frames(const std::vector<std::string>& args, FramePlan& plan, std::string& err);

/// The command line for one frame.
std::vector<std::string> args_for_frame(const FramePlan& plan, int frame);

}  // namespace bokehtool
