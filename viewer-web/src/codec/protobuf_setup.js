// Runs before the generated messages are defined (proto.js imports it first): 64-bit integers
// become plain numbers, in decoded values and in the defaults of unset fields alike.
import $protobuf from 'protobufjs/minimal.js';

$protobuf.util.Long = /** @type {any} */ (null);
$protobuf.configure();
