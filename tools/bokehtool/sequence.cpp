// sequence.cpp — frame-sequence expansion on OIIO's Filesystem helpers (parse_pattern,
// enumerate_sequence, scan_for_matching_filenames), the ones oiiotool uses.

#include "sequence.h"

#include <cstdio>
#include <regex>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/strutil.h>

namespace bokehtool {

using OIIO::Strutil::fmt::format;

static bool looks_like_pattern(const std::string& arg)
{
    static const std::regex printf_frame("%0*[0-9]*d");
    if (arg.empty() || arg[0] == '-')
        return false;
    return arg.find('#') != std::string::npos || arg.find('@') != std::string::npos
           || std::regex_search(arg, printf_frame);
}

bool plan_frames(const std::vector<std::string>& args, FramePlan& plan, std::string& err)
{
    plan = FramePlan();
    std::string frames_spec;
    for (size_t i = 0; i < args.size(); ++i) {
        if (args[i] == "--frames") {
            if (i + 1 >= args.size()) {
                err = "--frames: needs a frame list, e.g. 1-10 or 1-10x2";
                return false;
            }
            frames_spec = args[++i];
            continue;
        }
        plan.args.push_back(args[i]);
    }

    // --framepadding N: the digits of a '#' (parse_pattern's framepadding; 0 = its default,
    // 4). Checked, and refused when malformed, with the other global options.
    int padding = 0;
    for (size_t i = 0; i + 1 < plan.args.size(); ++i)
        if (plan.args[i] == "--framepadding") {
            OIIO::string_view n(plan.args[i + 1]);
            if (!OIIO::Strutil::parse_int(n, padding) || !n.empty() || padding < 1 || padding > 9)
                padding = 0;
        }

    std::string range_in_pattern;
    for (size_t i = 0; i < plan.args.size(); ++i) {
        const std::string& a = plan.args[i];
        if (!looks_like_pattern(a))
            continue;
        std::string normalized, range;
        if (!OIIO::Filesystem::parse_pattern(a.c_str(), padding, normalized, range)) {
            err = format("{}: malformed frame pattern", a);
            return false;
        }
        if (normalized == a && a.find('%') == std::string::npos)
            continue;  // '#' or '@' that is not a frame pattern
        // Exactly one integer conversion, as it is handed to snprintf below.
        static const std::regex one_frame("[^%]*%0*[0-9]*d[^%]*");
        if (!std::regex_match(normalized, one_frame)) {
            err = format("{}: a file name may hold only one frame pattern", a);
            return false;
        }
        plan.pattern_args.push_back(int(i));
        plan.normalized.push_back(normalized);
        if (range_in_pattern.empty())
            range_in_pattern = range;
    }
    if (plan.pattern_args.empty()) {
        if (!frames_spec.empty()) {
            err = "--frames: no argument holds a frame pattern (#, @ or %0Nd)";
            return false;
        }
        return true;
    }

    const std::string spec = frames_spec.empty() ? range_in_pattern : frames_spec;
    if (!spec.empty()) {
        if (!OIIO::Filesystem::enumerate_sequence(spec, plan.frames) || plan.frames.empty()) {
            err = format("--frames: '{}' is not a frame list (e.g. 1-10, 1-10x2, 3,5,8)", spec);
            return false;
        }
        return true;
    }
    // No range given: the frames are the files on disk matching the first pattern.
    std::vector<std::string> files;
    const std::string& first = plan.normalized.front();
    if (!OIIO::Filesystem::scan_for_matching_filenames(first, plan.frames, files)
        || plan.frames.empty()) {
        err = format("{}: no files match this frame pattern (give --frames for outputs)",
                     plan.args[size_t(plan.pattern_args.front())]);
        return false;
    }
    return true;
}

std::vector<std::string> args_for_frame(const FramePlan& plan, int frame)
{
    std::vector<std::string> out = plan.args;
    for (size_t k = 0; k < plan.pattern_args.size(); ++k) {
        char buf[4096];
        std::snprintf(buf, sizeof(buf), plan.normalized[k].c_str(), frame);
        out[size_t(plan.pattern_args[k])] = buf;
    }
    return out;
}

}  // namespace bokehtool
