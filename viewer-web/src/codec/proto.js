// The idms.v1 messages (protobufjs static code generated from protocol/idms.proto at build time),
// with 64-bit integers as plain numbers: ticks and frame sequences stay far below 2^53, and a Long
// object per field would allocate on every frame and compare by identity.
import './protobuf_setup.js';
import { idms } from '../gen/idms_pb.js';

export { idms };
