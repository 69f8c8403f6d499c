// A haptic device's process: a ToolClient on the installed client library.
// Joins the DDS domain (palpate's loopback configuration: the test runs it
// in a private network namespace) and looks for a model no daemon serves.
#include <chrono>
#include <cstdio>

#include "palpate/transport/tool_client.hpp"

int main() {
  palpate::ToolClient client(palpate::ToolClientOptions{});
  const auto model = client.wait_for_model("liver", std::chrono::milliseconds(200));
  std::printf("device_client: joined the domain; model 'liver' %s\n",
              model ? "described" : "not served (no palpated here)");
  return model ? 1 : 0;
}
