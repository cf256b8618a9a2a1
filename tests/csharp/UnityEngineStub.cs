// The few UnityEngine types client/csharp/Runtime/Unity/GmrLiveLink.cs uses,
// declared so that tests/csharp/csharp_test.py can compile that component with
// mcs (-define:UNITY_5_3_OR_NEWER) and catch a call that does not exist. A
// compile check only: nothing here behaves like Unity, and nothing runs it.
using System;

namespace UnityEngine
{
    public class Object { public string name; }
    public class Component : Object
    {
        public Transform transform { get { throw new NotImplementedException(); } }
        public T[] GetComponentsInChildren<T>() { throw new NotImplementedException(); }
    }
    public class Behaviour : Component { }
    public class MonoBehaviour : Behaviour { }
    public class Transform : Component
    {
        public Vector3 localPosition;
        public Quaternion localRotation;
        public void SetParent(Transform parent, bool worldPositionStays) { throw new NotImplementedException(); }
    }
    public class GameObject : Object
    {
        public GameObject(string name) { this.name = name; }
        public Transform transform { get { throw new NotImplementedException(); } }
    }
    public struct Vector3 { public Vector3(float x, float y, float z) { } }
    public struct Quaternion { public Quaternion(float x, float y, float z, float w) { } }
    public static class Debug { public static void LogWarning(object message) { } }
    [AttributeUsage(AttributeTargets.Field)]
    public class TooltipAttribute : Attribute { public TooltipAttribute(string tooltip) { } }
}
