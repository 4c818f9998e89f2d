#include "pipeline/points/points.h"
#include "iso/format.h"
