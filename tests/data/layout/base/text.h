#include "pipeline/points/points.h"
