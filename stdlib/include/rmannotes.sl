/* rmannotes.sl -- some published shaders include the RManNotes helpers under this name. */
#include "rmannotes.h"
