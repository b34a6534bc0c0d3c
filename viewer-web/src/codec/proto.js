// The idms.v1 messages (protobufjs static code generated from protocol/idms.proto at build time),
// with 64-bit integers decoded as plain numbers: ticks and frame sequences stay far below 2^53,
// and a Long object per field would allocate on every frame and compare by identity.
import $protobuf from 'protobufjs/minimal.js';
import { idms } from '../gen/idms_pb.js';

$protobuf.util.Long = /** @type {any} */ (null);
$protobuf.configure();

export { idms };
