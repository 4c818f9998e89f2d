// This process's memory as Linux reports it (/proc/self): the one place that reads it.
#pragma once

#include <cstdint>

namespace iso {

// Resident memory now, in bytes (statm's resident pages); fromFiles, when given, gets the part
// mapped from files (spilled arrays among them; the rest is anonymous memory). 0 where unknown.
uint64_t currentRssBytes(uint64_t* fromFiles = nullptr);

// Peak resident memory so far, in bytes (VmHWM); 0 where unknown.
uint64_t peakRssBytes();

// Reset the peak (writes "5" to clear_refs), so that a phase's peak can be read alone.
void resetPeakRss();

}  // namespace iso
