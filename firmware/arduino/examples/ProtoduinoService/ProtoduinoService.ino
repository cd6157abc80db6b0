// protoduino with a user service of your own (docs/services.md): the blinker of
// examples/blinker. This folder holds its handlers (blinker.c) and what
// `protoduino gen blinker.proto` wrote (blinker.pb.[ch], blinker_service.[ch]);
// the installed library's src/pd_config.h must say #define PD_FEATURE_USER 1.
//
//   import protoduino, blinker_pb2 as pb
//   from blinker_client import Blinker
//   with protoduino.Board.open("/dev/ttyACM0") as board:
//       Blinker(board).start_blink(pb.Blink(pin=13, period_ms=500))
#include <Protoduino.h>

void setup() {
  protoduino_begin();
}

void loop() {
  protoduino_poll();
}
