// sequence.cpp — frame-sequence expansion on OIIO's Filesystem helpers (parse_pattern,
// enumerate_sequence), the ones oiiotool uses; the files on disk are matched here
// (scan_frames, below, says why).

#include "sequence.h"

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
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

// How many frames a frame list may hold: a farm job's chunk, with room to spare. OIIO's
// enumerate_sequence builds the whole list (4 bytes a frame), so "1-2000000000" would take
// 8 GB before the first frame runs (found by the command-line fuzz target).
constexpr int64_t kMaxFrames = 1000000;

// An upper bound of the frames in `spec` (OIIO's grammar: items "A", "A-B", "A-BxS",
// "A-ByS", comma-separated): |B - A| / |S| + 1 for x, |B - A| + 1 otherwise. An item
// that does not parse counts 1 (enumerate_sequence then takes or refuses it).
static int64_t frames_bound(const std::string& spec)
{
    int64_t total = 0;
    for (std::string item : OIIO::Strutil::splits(spec, ",")) {
        item = std::string(OIIO::Strutil::strip(item));
        const char* p = item.c_str();
        char* end     = nullptr;
        const long long a = std::strtoll(p, &end, 10);
        if (end == p || *end != '-') {
            total += 1;
            continue;
        }
        p = end + 1;
        const long long b = std::strtoll(p, &end, 10);
        if (end == p) {
            total += 1;
            continue;
        }
        long double span = std::fabs(static_cast<long double>(b) - static_cast<long double>(a));
        if (*end == 'x') {
            const long long step = std::strtoll(end + 1, nullptr, 10);
            if (step != 0)
                span /= std::fabs(static_cast<long double>(step));
        }
        total += span >= kMaxFrames ? kMaxFrames + 1 : int64_t(span) + 1;
        if (total > kMaxFrames)
            break;
    }
    return total;
}

// The frames whose files exist: the entries of the pattern's directory that the pattern,
// printf'd with the number they hold, gives back exactly. Not OIIO's
// scan_for_matching_filenames: it makes a std::regex of the file name unescaped, so '.'
// matches any character and a name holding '*' runs for minutes (found by the command-line
// fuzz target: `bokehtool 'a********************@.exr' -o x.@.exr` ran past 60 s).
static bool scan_frames(const std::string& normalized, std::vector<int>& frames)
{
    const std::string dir  = OIIO::Filesystem::parent_path(normalized);
    const std::string name = OIIO::Filesystem::filename(normalized);
    const size_t pct       = name.find('%');
    const size_t conv_end  = pct == std::string::npos ? pct : name.find('d', pct);
    if (conv_end == std::string::npos)
        return false;  // the conversion is in the directory part: no file can match
    const std::string prefix = name.substr(0, pct), suffix = name.substr(conv_end + 1);
    std::vector<std::string> entries;
    OIIO::Filesystem::get_directory_entries(dir.empty() ? "." : dir, entries, false);
    for (const std::string& entry : entries) {
        const std::string f = OIIO::Filesystem::filename(entry);
        if (f.size() <= prefix.size() + suffix.size() || !OIIO::Strutil::starts_with(f, prefix)
            || !OIIO::Strutil::ends_with(f, suffix))
            continue;
        const std::string digits = f.substr(prefix.size(), f.size() - prefix.size() - suffix.size());
        char* end    = nullptr;
        errno        = 0;
        const long v = std::strtol(digits.c_str(), &end, 10);
        if (*end != '\0' || errno != 0 || v < INT_MIN || v > INT_MAX)
            continue;
        char again[4096];
        std::snprintf(again, sizeof(again), name.c_str(), int(v));
        if (f == again)
            frames.push_back(int(v));
    }
    std::sort(frames.begin(), frames.end());
    frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
    return !frames.empty();
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
        if (frames_bound(spec) > kMaxFrames) {
            err = format("--frames: '{}' holds more than {} frames, the most one run takes", spec,
                         kMaxFrames);
            return false;
        }
        if (!OIIO::Filesystem::enumerate_sequence(spec, plan.frames) || plan.frames.empty()) {
            err = format("--frames: '{}' is not a frame list (e.g. 1-10, 1-10x2, 3,5,8)", spec);
            return false;
        }
        return true;
    }
    // No range given: the frames are the files on disk matching the first pattern.
    if (!scan_frames(plan.normalized.front(), plan.frames)) {
        // Name the file looked for: "shot.####.exr" names 16 digits, not 4 (a '#' is
        // --framepadding digits, 4 by default, as in oiiotool; '@' is one digit).
        const std::string& typed = plan.args[size_t(plan.pattern_args.front())];
        char example[4096];
        std::snprintf(example, sizeof(example), plan.normalized.front().c_str(), 1);
        const size_t hashes = size_t(std::count(typed.begin(), typed.end(), '#'));
        err = format("{}: no files match this frame pattern (frame 1 would be {}{}; give --frames "
                     "for outputs)",
                     typed, example,
                     hashes > 1 ? format("; each '#' is {} digits, so shot.#.exr or shot.%04d.exr "
                                         "name 4",
                                         padding > 0 ? padding : 4)
                                : std::string());
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
