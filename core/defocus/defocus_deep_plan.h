// defocus_deep_plan.h — internal to the library: the deep defocus's plan
// (core/defocus/defocus_deep_plan.cpp): what the planner reads off a tidy deep image's
// samples, and the layers, views and ladder it chooses from them.
#pragma once

#include "defocus/defocus_layers.h"

#include <string>

#include <OpenImageIO/deepdata.h>

namespace bokeh::detail {

// The tidy image's channels a defocus reads (G and B fall back on R: a grey image).
struct DeepChannels {
    int r = -1, g = -1, b = -1, a = -1, z = -1, zback = -1;
};

/// The layers of a deep defocus and what they were chosen from.
struct DeepPlan {
    Membership m;            ///< the rungs and their reductions (a deep frame's pieces carry the shares)
    DefocusOptions options;  ///< the options with the planner's choices made (views)
    double layered_share = 0.0;  ///< of the pixels with samples: those recording one behind another
    double zlo = 0.0, zhi = 0.0;  ///< the samples' depth range (zlo > zhi: none)
};

/// The plan of a deep defocus with options `o` over the samples of `dd` (tidy), each of CoC
/// coc_of(depth): the report's CoC range, and under method=auto the views and ladder the
/// content asks for (defocus_deep_plan.cpp's measurements). False + `err` as
/// deep_layer_plan says (too many reference steps; exact rungs over volumes).
bool plan_deep_layers(DeepPlan& plan, const OIIO::DeepData& dd, const DeepChannels& ch, const CocOfDepth& coc_of,
                      const DefocusOptions& o, DefocusReport& rep, std::string& err);

}  // namespace bokeh::detail
