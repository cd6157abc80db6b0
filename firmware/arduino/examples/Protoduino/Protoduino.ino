// The whole protoduino firmware: the host (protoduino Python package) does the rest.
//
//   import protoduino
//   with protoduino.Board.open("/dev/ttyACM0") as board:
//       board.servo(9, safe=90).write(45)
#include <Protoduino.h>

void setup() {
  protoduino_begin();
}

void loop() {
  protoduino_poll();
}
