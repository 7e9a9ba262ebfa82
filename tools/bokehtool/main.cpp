// bokehtool — the OpenBokeh command line. All the work is in Host (host.h); a failure
// that escapes it (an exception while loading plugins, say) still ends in one line.

#include "host.h"

#include <exception>
#include <iostream>
#include <string>
#include <vector>

int main(int argc, char* argv[])
{
    try {
        std::vector<std::string> args(argv + 1, argv + argc);
        bokehtool::Host host;
        return host.main(args);
    } catch (const std::exception& e) {
        const std::string what = e.what();
        std::cerr << "bokehtool ERROR: " << what.substr(0, what.find('\n')) << "\n";
    } catch (...) {
        std::cerr << "bokehtool ERROR: failed with an unknown exception\n";
    }
    return 1;
}
