/* arbor test shim (not part of any shader collection): K-3D ships Advanced RenderMan's
 * noises.h renamed to k3d_noises.h; map it to the noises.h embedded in arbor. */
#include "noises.h"
