// fuzz_command_line.cpp — libFuzzer target: bokehtool's command-line grammar and option
// parser, through the host's own pass 1 (Host::check_only: frame planning, OIIO ArgParse,
// the registry's lookup, bokeh::parse_options against every command's typed specs, the
// stack-depth simulation, the global options). Nothing is read, run or written.
//
// Input: the arguments after the program name, separated by NUL bytes (as argv holds
// them). The built-in plugins are loaded from the build tree as bokehtool loads them (the
// target sits beside bokehtool in bin/), so every registered command and option is there.
// A fresh Host a run: no state leaks between inputs.
//
// Instrumented: tools/bokehtool/{host,sequence,guard,help_markdown}.cpp and core/plugin/plugin.cpp;
// the rest of libOpenBokeh and the plugin modules are the Release build's.
#include "host.h"

#include <cstdint>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include <OpenImageIO/imageio.h>

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    OIIO::attribute("threads", 1);
    // The one-line errors of rejected lines: thousands a second, not wanted on the console
    // (BOKEH_FUZZ_VERBOSE=1 shows them, to see what an input does).
    if (!std::getenv("BOKEH_FUZZ_VERBOSE")) {
        std::cerr.rdbuf(nullptr);
        std::cout.rdbuf(nullptr);
    }
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    if (size > 4096)  // a command line, not a file
        return 0;
    std::vector<std::string> args;
    std::string word;
    for (size_t i = 0; i < size; ++i) {
        if (data[i] == 0) {
            args.push_back(word);
            word.clear();
        } else {
            word.push_back(char(data[i]));
        }
    }
    args.push_back(word);
    bokehtool::Host host;
    const bool ok = host.check_only(args);
    if (std::getenv("BOKEH_FUZZ_VERBOSE"))
        std::cerr << (ok ? "accepted\n" : "refused\n");
    return 0;
}
