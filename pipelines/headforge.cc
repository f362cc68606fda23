#include "pipelines/commands.h"

int main(int argc, char** argv) { return headforge::HeadForgeMain(argc, argv); }
