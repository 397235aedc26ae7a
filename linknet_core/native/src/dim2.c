/* The 2-D copies of the DIM-generic stages: planar scenes run in their plane's coordinates. */
#define DIM 2
#include "stages_list.h"
