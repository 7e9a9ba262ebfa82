// A shared module that is not an OpenBokeh plugin (no entry points).
extern "C" int some_other_function() { return 42; }
