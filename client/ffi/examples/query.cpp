// query.cpp: ask a running dyfosd where the viewer should put its camera, in C++17.
//
//   c++ -std=c++17 query.cpp $(pkg-config --cflags --libs dyfos) -o query
//   ./query SCENARIO.json [PREFIX [DOMAIN [SEED]]]
//
// Uploads the scenario's map (SPEC §11), queries its rover, and prints the answer
// as `dyfos solve --seed SEED SCENARIO.json` prints it.
#include "dyfos.hpp"

#include <fstream>
#include <iostream>
#include <sstream>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: " << argv[0] << " SCENARIO.json [PREFIX [DOMAIN [SEED]]]\n";
    return 2;
  }
  std::ifstream file(argv[1]);
  std::stringstream scenario;
  scenario << file.rdbuf();
  try {
    dyfos::Client client(argc > 2 ? argv[2] : "dyfos/",
                         argc > 3 ? std::optional<std::string>(argv[3]) : std::nullopt,
                         std::chrono::seconds(5));
    auto [map, version] = client.upload_scenario(scenario.str());
    auto request = dyfos::RendezvousRequest::from_scenario(scenario.str(), map);
    request.seed = argc > 4 ? std::stoull(argv[4]) : 0;
    request.expected_version = version;
    dyfos::Answer answer = client.rendezvous(request);
    std::cout << answer.to_json() << "\n";
  } catch (const dyfos::UnknownMapError& e) {
    std::cerr << "the map is gone: " << e.what() << "\n";
    return 1;
  } catch (const dyfos::Error& e) {
    std::cerr << "dyfos: " << e.name() << ": " << e.what() << "\n";
    return 1;
  }
  return 0;
}
