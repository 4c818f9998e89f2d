// sRGB transfer functions for readers and writers; defined with the other quantizers in
// format/include/iso/quantize.h so that every side of the file agrees.
#pragma once

#include "iso/quantize.h"
