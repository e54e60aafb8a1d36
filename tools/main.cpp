#include "tools/cli.hpp"

#include <iostream>

int main(int argc, char** argv) { return lockstep::cli::main(argc, argv, std::cout, std::cerr); }
