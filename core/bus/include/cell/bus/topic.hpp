#pragma once

#include <string>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/topics.hpp"

namespace cell::bus {

/// A typed topic of one participant. Throws BusError on setup failure.
template <IdlType T>
class Topic {
 public:
  Topic(const Participant& participant, const TopicDef<T>& def)
      : name_(def.name),
        entity_(check_created(
            dds_create_topic(participant.get(), kDescriptor<T>, def.name, nullptr, nullptr),
            std::string("create topic '") + def.name + "'")) {}

  dds_entity_t get() const noexcept { return entity_.get(); }
  const std::string& name() const noexcept { return name_; }

 private:
  std::string name_;
  Entity entity_;
};

}  // namespace cell::bus
