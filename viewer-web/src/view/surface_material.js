// The surface's material: each vertex's colour-map value (entry / 255) and smooth normal
// interpolated, the map's entry looked up per pixel (nearest texel: the table's colours exactly),
// lit per pixel by display.json's ambient, grazing key and fill lights in the world frame; back
// faces in their own colour. The arithmetic and the output (no colour-space conversion: the map
// is sRGB and written as it is) are idms-render's surface program's (viewer-offscreen/src/
// renderer.cc), so the two viewers draw the same colours. three.js's lit materials were rejected:
// their physically based light and sRGB conversion would make another colour of each entry.
import * as THREE from 'three';
import { display, kMapRgba, srgbBytes } from './display.js';

const kVertex = /* glsl */ `
attribute float value;
varying float vValue;
varying vec3 vNormal;
void main() {
  vValue = value;
  vNormal = mat3(modelMatrix) * normal;
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}
`;
const kFragment = /* glsl */ `
uniform sampler2D colourMap;
uniform bool useMap;
uniform vec3 plain, back, keyTowards, fillTowards;
uniform float ambient, key, fill;
varying float vValue;
varying vec3 vNormal;
void main() {
  vec3 n = normalize(vNormal);
  vec3 albedo = back;
  if (gl_FrontFacing) {
    float index = floor(clamp(vValue, 0.0, 1.0) * 255.0 + 0.5);
    albedo = useMap ? texture2D(colourMap, vec2((index + 0.5) / 256.0, 0.5)).rgb : plain;
  } else {
    n = -n;
  }
  float light = ambient + key * max(dot(n, keyTowards), 0.0) + fill * max(dot(n, fillTowards), 0.0);
  gl_FragColor = vec4(min(albedo * light, vec3(1.0)), 1.0);
}
`;

/** An sRGB hex as a vector of 0..1, untouched by colour management. @param {string} hex */
const rgb = (hex) => new THREE.Vector3(...srgbBytes(hex).map((x) => x / 255));
/** @param {number[]} v */
const unit = (v) => new THREE.Vector3(v[0], v[1], v[2]).normalize();

/** @returns {THREE.ShaderMaterial} with a `useMap` uniform: false draws display.json's plain colour */
export function surfaceMaterial() {
  const map = new THREE.DataTexture(kMapRgba, kMapRgba.length / 4, 1, THREE.RGBAFormat, THREE.UnsignedByteType);
  map.magFilter = THREE.NearestFilter;
  map.minFilter = THREE.NearestFilter;
  map.colorSpace = THREE.NoColorSpace;
  map.needsUpdate = true;
  const light = display.light;
  return new THREE.ShaderMaterial({
    vertexShader: kVertex,
    fragmentShader: kFragment,
    side: THREE.DoubleSide,
    uniforms: {
      colourMap: { value: map },
      useMap: { value: true },
      plain: { value: rgb(light.plain_srgb) },
      back: { value: rgb(light.back_srgb) },
      keyTowards: { value: unit(light.key.towards) },
      fillTowards: { value: unit(light.fill.towards) },
      ambient: { value: light.ambient },
      key: { value: light.key.intensity },
      fill: { value: light.fill.intensity },
    },
  });
}
