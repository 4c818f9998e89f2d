#include "pipeline/output/chunks.h"
#include "tools/iso/text.h"
