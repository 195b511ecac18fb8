// Everything a Reflex process needs to be on the bus: Participant, Writer<T>, Reader<T>,
// BusConfig, StopOnSignal, HeartbeatPublisher and the topic types (<reflex/msg/*.h>). See idl/README.md.
#pragma once

#include "reflex/bus/config.hpp"
#include "reflex/bus/error.hpp"
#include "reflex/bus/heartbeat.hpp"
#include "reflex/bus/identity.hpp"
#include "reflex/bus/log_limit.hpp"
#include "reflex/bus/participant.hpp"
#include "reflex/bus/security.hpp"
#include "reflex/bus/signals.hpp"
#include "reflex/bus/topics.hpp"
