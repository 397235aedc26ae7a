/* The 3-D copies of the DIM-generic stages: every scene that is not planar. */
#define DIM 3
#include "stages_list.h"
