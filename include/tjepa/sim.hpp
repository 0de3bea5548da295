#pragma once
// The simulators: skins with a contact model (SimulatedSkin: indenters pressed on a layout's
// taxels, with labels) and the Allegro hand with Xela skins grasping objects (SimulatedHand).
// They make data where there is none (tests, the demo, the paper's protocol); the algorithm in
// <tjepa/tjepa.hpp> never includes them.
#include "tjepa/tjepa.hpp"

#include "tjepa/sim/contact_model.hpp"
#include "tjepa/sim/simulated_dataset.hpp"
#include "tjepa/sim/simulated_skin.hpp"
#include "tjepa/sim/grasp_objects.hpp"
#include "tjepa/sim/grasping_hand.hpp"
