#include <iostream>

#include "session.hpp"

// cellctl: see session.hpp (global options) and commands.hpp (command groups).
int main(int argc, char** argv) { return cell::cellctl::run(argc, argv, std::cout, std::cerr); }
