// bokehtool — the OpenBokeh command line. All the work is in Host (host.h).

#include "host.h"

#include <string>
#include <vector>

int main(int argc, char* argv[])
{
    std::vector<std::string> args(argv + 1, argv + argc);
    bokehtool::Host host;
    return host.main(args);
}
